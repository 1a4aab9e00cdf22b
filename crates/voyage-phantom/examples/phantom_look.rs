//! Writes pictures of the phantoms into /tmp/phantom-look/ (PNG, 8-bit grey) for a human
//! to look at: axial, coronal and sagittal slices with an abdomen window, and projections
//! of the lumen mask (the coronal one should show the colon's upside-down U).
//!
//! `cargo run --release -p voyage-phantom --example phantom_look [pipe|colon|small|all]`;
//! `... phantom_look time` times the generators; `... phantom_look anatomy` prints the
//! colon's course (lengths, tightest bend, closest loops) for tuning it; `... variant NAME
//! small prone opacified tube table folds fluid collapsed=SEG filled=SEG quantize=HU seed=N`
//! draws slices through what the newer options add (the ileocaecal valve, the rectal
//! catheter, each gap in the gas, each skin fold) and lists the truth; `... free Z0 Z1` maps the room around the colon
//! and `... room` (knots on stdin) checks a small-bowel course, for placing the loops;
//! `... save OUT.nii [small] [fluid] [collapsed] [seed=N]` writes the CT as the CLI does.

use std::{io::Write, path::Path, time::Instant};

use voyage_core::Volume;
use voyage_phantom::{self as phantom, ColonOptions, Phantom};

type Res<T> = Result<T, Box<dyn std::error::Error>>;

/// A grey image, row-major, top row first.
struct Image {
    w: usize,
    h: usize,
    px: Vec<u8>,
}

fn main() -> Res<()> {
    let which = std::env::args().nth(1).unwrap_or_else(|| "all".into());
    let dir = Path::new("/tmp/phantom-look");
    std::fs::create_dir_all(dir)?;
    if which == "time" {
        return time();
    }
    if which == "free" {
        let from: f64 = std::env::args()
            .nth(2)
            .and_then(|a| a.parse().ok())
            .unwrap_or(20.0);
        let to: f64 = std::env::args()
            .nth(3)
            .and_then(|a| a.parse().ok())
            .unwrap_or(260.0);
        print!("{}", phantom::colon::free_space_map(from, to)?);
        return Ok(());
    }
    if which == "room" {
        // Knots "x,y,z x,y,z ..." on stdin (one loop per line, radius first).
        for line in std::io::stdin().lines() {
            let line = line?;
            let mut it = line.split_whitespace();
            let Some(r) = it.next().and_then(|r| r.parse::<f64>().ok()) else {
                continue;
            };
            let knots: Vec<[f64; 3]> = it
                .map(|k| {
                    let v: Vec<f64> = k.split(',').filter_map(|x| x.parse().ok()).collect();
                    [v[0], v[1], v[2]]
                })
                .collect();
            print!("{}", phantom::colon::loop_room_report(&knots, r)?);
        }
        return Ok(());
    }
    if which == "save" {
        // `save OUT.nii [small] [collapsed] [fluid] [seed=N]`: the CT as the CLI writes it.
        let args: Vec<String> = std::env::args().skip(2).collect();
        let has = |w: &str| args.iter().any(|a| a == w);
        let seed = args
            .iter()
            .find_map(|a| a.strip_prefix("seed=")?.parse().ok())
            .unwrap_or(1);
        let opts = ColonOptions {
            seed,
            small: has("small"),
            tagged_fluid: has("fluid"),
            collapsed: if has("collapsed") {
                vec!["descending".into()]
            } else {
                Vec::new()
            },
            ..ColonOptions::default()
        };
        let t = Instant::now();
        let p = phantom::colon(&opts)?;
        eprintln!("made in {:.2} s", t.elapsed().as_secs_f64());
        voyage_io::nifti::save(Path::new(&args[0]), &p.ct)?;
        voyage_io::nifti::save(Path::new(&format!("{}.lumen.nii.gz", args[0])), &p.lumen)?;
        return Ok(());
    }
    if which == "variant" {
        // `variant NAME [small] [fluid] [prone] [opacified] [tube] [table] [folds]
        // [collapsed=SEG]... [filled=SEG]... [quantize=HU] [seed=N]`: pictures of one variant.
        let args: Vec<String> = std::env::args().skip(2).collect();
        let opts = variant_options(&args[1..]);
        let t = Instant::now();
        let p = phantom::colon(&opts)?;
        eprintln!("{}: made in {:.2} s", args[0], t.elapsed().as_secs_f64());
        look_variant(&p, dir, &args[0])?;
        return Ok(());
    }
    if which == "anatomy" {
        print!("{}", phantom::colon::anatomy_report(false)?);
        return Ok(());
    }
    if which == "pipe" || which == "all" {
        let t = Instant::now();
        let p = phantom::pipe(1)?;
        eprintln!("pipe: {:.2} s", t.elapsed().as_secs_f64());
        look(&p, dir, "pipe")?;
    }
    if which == "small" || which == "all" {
        let t = Instant::now();
        let p = phantom::colon(&ColonOptions {
            small: true,
            tagged_fluid: true,
            ..ColonOptions::default()
        })?;
        eprintln!("small colon: {:.2} s", t.elapsed().as_secs_f64());
        look(&p, dir, "small")?;
        let p = phantom::colon(&ColonOptions {
            small: true,
            collapsed: vec!["descending".into()],
            ..ColonOptions::default()
        })?;
        look(&p, dir, "small-collapsed")?;
    }
    if which == "colon" || which == "all" {
        let t = Instant::now();
        let p = phantom::colon(&ColonOptions::default())?;
        eprintln!("colon: {:.2} s", t.elapsed().as_secs_f64());
        look(&p, dir, "colon")?;
        let p = phantom::colon(&ColonOptions {
            tagged_fluid: true,
            ..ColonOptions::default()
        })?;
        look(&p, dir, "colon-fluid")?;
    }
    Ok(())
}

/// Options from words: small, fluid, prone, opacified, tube, table, folds, collapsed=SEG,
/// filled=SEG, quantize=HU, seed=N, noise=HU.
fn variant_options(args: &[String]) -> ColonOptions {
    let mut o = ColonOptions::default();
    for a in args {
        match a.split_once('=') {
            Some(("collapsed", v)) => o.collapsed.push(v.into()),
            Some(("filled", v)) => o.fluid_filled.push(v.into()),
            Some(("quantize", v)) => o.quantize_hu = v.parse().ok(),
            Some(("seed", v)) => o.seed = v.parse().unwrap_or(1),
            Some(("noise", v)) => o.noise_hu = v.parse().unwrap_or(20.0),
            _ => match a.as_str() {
                "small" => o.small = true,
                "fluid" => o.tagged_fluid = true,
                "prone" => o.prone = true,
                "opacified" => o.opacified_small_bowel = true,
                "tube" => o.rectal_tube = true,
                "table" => o.table = true,
                "folds" => o.skin_folds = true,
                _ => eprintln!("ignored: {a}"),
            },
        }
    }
    o
}

/// Slices through what the newer options add: the ileocaecal valve (axial, coronal,
/// sagittal), the rectal catheter (sagittal, coronal), each gap in the gas (coronal through
/// its middle), each skin fold (axial where skin closes over it, or through its middle), and
/// counts of the labels.
fn look_variant(p: &Phantom, dir: &Path, name: &str) -> Res<()> {
    let t = &p.truth;
    let s = p.ct.spacing();
    // Small phantoms are drawn three times larger.
    let f = if p.ct.dims()[0] <= 128 { 3 } else { 1 };
    let save = |img: &Image, path: &Path| save(&zoom(img, f), path);
    let dims = p.ct.dims();
    let vox =
        |x: [f64; 3]| [0, 1, 2].map(|a| ((x[a] / s[a]).round().max(0.0) as usize).min(dims[a] - 1));
    let counts = phantom::label_counts(&p.labels);
    let names = phantom::label::legend();
    let listed: Vec<String> = names
        .iter()
        .filter(|(v, _)| counts[*v as usize] > 0)
        .map(|(v, n)| format!("{n} {}", counts[*v as usize]))
        .collect();
    eprintln!(
        "{name}: {} ({}), labels: {}",
        t.position,
        if t.scale < 1.0 { "small" } else { "full" },
        listed.join(", ")
    );
    for pl in &t.fluid_pools {
        eprintln!(
            "  pool {} arcs {:.0}..{:.0}, level y = {:.1}, gravity {:?}, {:.0} HU",
            pl.segment, pl.start_arc_mm, pl.end_arc_mm, pl.level_y_mm, pl.gravity_lps, pl.hu
        );
    }
    for g in &t.gas_gaps {
        eprintln!(
            "  gap {} in the {} arcs {:.0}..{:.0}",
            g.kind, g.segment, g.start_arc_mm, g.end_arc_mm
        );
    }
    for l in &t.small_bowel_loops {
        eprintln!(
            "  loop r {:.1} mm, {:.0} mm long, {:.0} HU{}{}",
            l.radius_mm,
            l.length_mm,
            l.hu,
            if l.enters_cecum {
                ", into the caecum"
            } else {
                ""
            },
            if l.touches_colon {
                ", touches the colon"
            } else {
                ""
            }
        );
    }
    if let Some(v) = t.ileocecal_valve_mm {
        let [i, j, k] = vox(v);
        eprintln!("  valve at {v:.1?} (voxel {i} {j} {k})");
        save(
            &axial(&p.ct, k),
            &dir.join(format!("{name}-valve-axial.png")),
        )?;
        save(
            &coronal(&p.ct, j),
            &dir.join(format!("{name}-valve-coronal.png")),
        )?;
        save(
            &sagittal(&p.ct, i),
            &dir.join(format!("{name}-valve-sagittal.png")),
        )?;
        for f in [0.15, 0.3, 0.45, 0.6] {
            let k = ((dims[2] as f64 * f) as usize).min(dims[2] - 1);
            save(
                &axial(&p.ct, k),
                &dir.join(format!("{name}-axial-{k:03}.png")),
            )?;
        }
    }
    if let Some(c) = &t.rectal_tube {
        let [i, j, _] = vox(c.tip_mm);
        eprintln!("  rectal tube tip {:.1?} exit {:.1?}", c.tip_mm, c.exit_mm);
        save(
            &sagittal(&p.ct, i),
            &dir.join(format!("{name}-tube-sagittal.png")),
        )?;
        save(
            &coronal(&p.ct, vox(c.exit_mm)[1]),
            &dir.join(format!("{name}-tube-coronal.png")),
        )?;
        let _ = j;
        for k in [0, 1, 2, 3, 5, 8] {
            let k = k.min(dims[2] - 1);
            save(
                &zoom(
                    &crop(&axial(&p.ct, k), vox(c.exit_mm)[0], vox(c.exit_mm)[1], 24),
                    4,
                ),
                &dir.join(format!("{name}-tube-axial-{k:03}.png")),
            )?;
        }
    }
    if let Some(tb) = &t.table {
        eprintln!(
            "  table {} y {:.1}..{:.1}, skin flat on it over x {:.1}..{:.1}",
            tb.side, tb.top_y_mm, tb.bottom_y_mm, tb.contact_x_mm[0], tb.contact_x_mm[1]
        );
    }
    for (n, f) in t.skin_folds.iter().enumerate() {
        let l = f
            .closed_mm
            .map_or(0.5 * (f.span_mm[0] + f.span_mm[1]), |[a, b]| 0.5 * (a + b));
        let at = [0, 1, 2].map(|a| f.mouth_mm[a] + f.inward[a] * 0.5 * f.depth_mm + f.along[a] * l);
        let [_, _, k] = vox(at);
        eprintln!(
            "  {} fold at {:.1?}: {:.0} mm deep, {:.1} mm wide, along {:.1?} over {:.0?}, closed over {:.0?}",
            f.region, f.mouth_mm, f.depth_mm, f.width_mm, f.along, f.span_mm, f.closed_mm
        );
        save(
            &axial(&p.ct, k),
            &dir.join(format!("{name}-fold{n}-{}-axial-{k:03}.png", f.region)),
        )?;
    }
    for (n, g) in t.gas_gaps.iter().enumerate() {
        let mid = 0.5 * (g.start_arc_mm + g.end_arc_mm);
        let at = t
            .centerline_arc_mm
            .partition_point(|&a| a < mid)
            .min(t.centerline_mm.len() - 1);
        let [_, j, _] = vox(t.centerline_mm[at]);
        save(
            &coronal(&p.ct, j),
            &dir.join(format!(
                "{name}-gap{n}-{}-{}-coronal.png",
                g.kind, g.segment
            )),
        )?;
    }
    save(
        &coronal(&p.ct, dims[1] / 2),
        &dir.join(format!("{name}-coronal-mid.png")),
    )?;
    save(
        &project(&p.lumen, 1),
        &dir.join(format!("{name}-lumen-coronal-projection.png")),
    )?;
    let bright = Volume::from_vec(
        p.ct.geometry().clone(),
        p.ct.data().iter().map(|&v| u8::from(v >= 200)).collect(),
    )?;
    save(
        &project(&bright, 1),
        &dir.join(format!("{name}-bright-coronal-projection.png")),
    )?;
    Ok(())
}

/// Generation times (best of three) of the small colon, the full colon and the pipe.
fn time() -> Res<()> {
    let best = |f: &dyn Fn() -> Res<()>| -> Res<f64> {
        let mut best = f64::INFINITY;
        for _ in 0..3 {
            let t = Instant::now();
            f()?;
            best = best.min(t.elapsed().as_secs_f64());
        }
        Ok(best)
    };
    let threads = rayon::current_num_threads();
    let small = best(&|| {
        phantom::colon(&ColonOptions {
            small: true,
            ..ColonOptions::default()
        })
        .map(drop)
        .map_err(Into::into)
    })?;
    let full = best(&|| {
        phantom::colon(&ColonOptions::default())
            .map(drop)
            .map_err(Into::into)
    })?;
    let pipe = best(&|| phantom::pipe(1).map(drop).map_err(Into::into))?;
    println!(
        "{threads} threads: small colon {small:.3} s, full colon {full:.3} s, pipe {pipe:.3} s"
    );
    let every = |small: bool| ColonOptions {
        small,
        prone: true,
        tagged_fluid: true,
        opacified_small_bowel: true,
        collapsed: vec!["sigmoid".into(), "descending".into()],
        fluid_filled: vec!["transverse".into()],
        rectal_tube: true,
        quantize_hu: Some(8.0),
        ..ColonOptions::default()
    };
    let small_all = best(&|| phantom::colon(&every(true)).map(drop).map_err(Into::into))?;
    let full_all = best(&|| phantom::colon(&every(false)).map(drop).map_err(Into::into))?;
    println!("every option: small colon {small_all:.3} s, full colon {full_all:.3} s");
    Ok(())
}

fn look(p: &Phantom, dir: &Path, name: &str) -> Res<()> {
    let [nx, ny, nz] = p.ct.dims();
    let t = &p.truth;
    eprintln!(
        "{name}: length {:.0} mm, {} folds, {} polyps, lumen {} voxels, gap {:.1} mm",
        t.centerline_length_mm,
        t.folds,
        t.polyps.len(),
        t.lumen_voxels,
        t.min_part_gap_mm
    );
    save(
        &axial(&p.ct, nz / 2),
        &dir.join(format!("{name}-axial-mid.png")),
    )?;
    save(
        &coronal(&p.ct, ny / 2),
        &dir.join(format!("{name}-coronal-mid.png")),
    )?;
    save(
        &sagittal(&p.ct, nx / 2),
        &dir.join(format!("{name}-sagittal-mid.png")),
    )?;
    for f in [0.1, 0.3, 0.7, 0.95] {
        let k = ((nz as f64 * f) as usize).min(nz - 1);
        save(
            &axial(&p.ct, k),
            &dir.join(format!("{name}-axial-{k:03}.png")),
        )?;
    }
    save(
        &project(&p.lumen, 1),
        &dir.join(format!("{name}-lumen-coronal-projection.png")),
    )?;
    save(
        &project(&p.lumen, 2),
        &dir.join(format!("{name}-lumen-axial-projection.png")),
    )?;
    // Close-ups (×4) of an axial and a coronal slice through each polyp.
    for (n, pol) in t.polyps.iter().enumerate() {
        let s = p.ct.spacing();
        let [i, j, k] =
            [0, 1, 2].map(|a| ((pol.center_mm[a] / s[a]).round() as usize).min(p.ct.dims()[a] - 1));
        let ax = crop(&axial(&p.ct, k), i, j, 24);
        let row = ((nz - 1 - k) as f64 * s[2] / s[0]).round() as usize;
        let co = crop(&coronal(&p.ct, j), i, row, 24);
        let tag = format!(
            "{:.0}mm-{}{}",
            pol.diameter_mm,
            pol.segment,
            if pol.behind_fold { "-behind-fold" } else { "" }
        );
        save(
            &zoom(&ax, 4),
            &dir.join(format!("{name}-polyp{n}-{tag}-axial.png")),
        )?;
        save(
            &zoom(&co, 4),
            &dir.join(format!("{name}-polyp{n}-{tag}-coronal.png")),
        )?;
    }
    Ok(())
}

/// The square of half-size `half` around (cx, cy), clipped to the image.
fn crop(img: &Image, cx: usize, cy: usize, half: usize) -> Image {
    let x0 = cx.saturating_sub(half);
    let y0 = cy.saturating_sub(half);
    let x1 = (cx + half).min(img.w - 1);
    let y1 = (cy + half).min(img.h - 1);
    let px = (y0..=y1)
        .flat_map(|y| (x0..=x1).map(move |x| (x, y)))
        .map(|(x, y)| img.px[x + img.w * y])
        .collect();
    Image {
        w: x1 - x0 + 1,
        h: y1 - y0 + 1,
        px,
    }
}

/// Nearest-neighbour enlargement.
fn zoom(img: &Image, f: usize) -> Image {
    let (w, h) = (img.w * f, img.h * f);
    let px = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| img.px[x / f + img.w * (y / f)])
        .collect();
    Image { w, h, px }
}

/// Abdomen-ish window: −1000 → 0, +400 → 255.
fn window(hu: i16) -> u8 {
    ((hu as f64 + 1000.0) / 1400.0 * 255.0).clamp(0.0, 255.0) as u8
}

/// Axial slice k: patient right (small x) on the left, anterior (small y) on top.
fn axial(ct: &Volume<i16>, k: usize) -> Image {
    let [nx, ny, _] = ct.dims();
    let px = (0..ny)
        .flat_map(|j| (0..nx).map(move |i| (i, j)))
        .map(|(i, j)| window(ct.get(i, j, k)))
        .collect();
    Image { w: nx, h: ny, px }
}

/// Coronal slice j: superior on top, resampled to square pixels of the x spacing.
fn coronal(ct: &Volume<i16>, j: usize) -> Image {
    let [nx, _, nz] = ct.dims();
    let s = ct.spacing();
    let h = (nz as f64 * s[2] / s[0]).round() as usize;
    let px = (0..h)
        .flat_map(|r| (0..nx).map(move |i| (i, r)))
        .map(|(i, r)| {
            let k = nz - 1 - ((r as f64 * s[0] / s[2]) as usize).min(nz - 1);
            window(ct.get(i, j, k))
        })
        .collect();
    Image { w: nx, h, px }
}

/// Sagittal slice i: superior on top, anterior on the left.
fn sagittal(ct: &Volume<i16>, i: usize) -> Image {
    let [_, ny, nz] = ct.dims();
    let s = ct.spacing();
    let h = (nz as f64 * s[2] / s[1]).round() as usize;
    let px = (0..h)
        .flat_map(|r| (0..ny).map(move |j| (j, r)))
        .map(|(j, r)| {
            let k = nz - 1 - ((r as f64 * s[1] / s[2]) as usize).min(nz - 1);
            window(ct.get(i, j, k))
        })
        .collect();
    Image { w: ny, h, px }
}

/// Projection of a mask along `axis` (1 = y: coronal view; 2 = z: axial view): brighter
/// where more mask voxels lie on the ray, so overlapping loops show.
fn project(m: &Volume<u8>, axis: usize) -> Image {
    let [nx, ny, nz] = m.dims();
    let s = m.spacing();
    let count = |i: usize, r: usize| -> usize {
        match axis {
            1 => (0..ny).filter(|&j| m.get(i, j, r) != 0).count(),
            _ => (0..nz).filter(|&k| m.get(i, r, k) != 0).count(),
        }
    };
    let (h, rows): (usize, Vec<usize>) = if axis == 1 {
        let h = (nz as f64 * s[2] / s[0]).round() as usize;
        (
            h,
            (0..h)
                .map(|r| nz - 1 - ((r as f64 * s[0] / s[2]) as usize).min(nz - 1))
                .collect(),
        )
    } else {
        (ny, (0..ny).collect())
    };
    let counts: Vec<usize> = rows
        .iter()
        .flat_map(|&r| (0..nx).map(move |i| (i, r)))
        .map(|(i, r)| count(i, r))
        .collect();
    let max = counts.iter().copied().max().unwrap_or(1).max(1) as f64;
    let px = counts
        .iter()
        .map(|&c| {
            if c == 0 {
                0
            } else {
                (50.0 + 205.0 * c as f64 / max) as u8
            }
        })
        .collect();
    Image { w: nx, h, px }
}

/// Minimal PNG writer (grey, 8-bit, zlib via flate2).
fn save(img: &Image, path: &Path) -> Res<()> {
    let mut raw = Vec::with_capacity((img.w + 1) * img.h);
    for row in img.px.chunks(img.w) {
        raw.push(0u8);
        raw.extend_from_slice(row);
    }
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
    z.write_all(&raw)?;
    let idat = z.finish()?;
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&(img.w as u32).to_be_bytes());
    ihdr.extend_from_slice(&(img.h as u32).to_be_bytes());
    ihdr.extend_from_slice(&[8, 0, 0, 0, 0]);
    chunk(&mut out, b"IHDR", &ihdr);
    chunk(&mut out, b"IDAT", &idat);
    chunk(&mut out, b"IEND", &[]);
    std::fs::write(path, out)?;
    Ok(())
}

fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend_from_slice(&(data.len() as u32).to_be_bytes());
    let start = out.len();
    out.extend_from_slice(kind);
    out.extend_from_slice(data);
    let crc = crc32(&out[start..]);
    out.extend_from_slice(&crc.to_be_bytes());
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut c = 0xFFFF_FFFFu32;
    for &b in bytes {
        c ^= b as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}
