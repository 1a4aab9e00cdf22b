//! Writes pictures of the phantoms into /tmp/phantom-look/ (PNG, 8-bit grey) for a human
//! to look at: axial, coronal and sagittal slices with an abdomen window, and projections
//! of the lumen mask (the coronal one should show the colon's upside-down U).
//!
//! `cargo run --release -p voyage-core --example phantom_look [pipe|colon|small|all]`;
//! `... phantom_look time` times the generators; `... phantom_look anatomy` prints the
//! colon's course (lengths, tightest bend, closest loops) for tuning it.

use std::io::Write;
use std::path::Path;
use std::time::Instant;

use voyage_core::Volume;
use voyage_core::phantom::{self, ColonOptions, Phantom};

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
        let p = phantom::colon(&ColonOptions { small: true, tagged_fluid: true, ..ColonOptions::default() })?;
        eprintln!("small colon: {:.2} s", t.elapsed().as_secs_f64());
        look(&p, dir, "small")?;
        let p = phantom::colon(&ColonOptions { small: true, collapsed_segment: true, ..ColonOptions::default() })?;
        look(&p, dir, "small-collapsed")?;
    }
    if which == "colon" || which == "all" {
        let t = Instant::now();
        let p = phantom::colon(&ColonOptions::default())?;
        eprintln!("colon: {:.2} s", t.elapsed().as_secs_f64());
        look(&p, dir, "colon")?;
        let p = phantom::colon(&ColonOptions { tagged_fluid: true, ..ColonOptions::default() })?;
        look(&p, dir, "colon-fluid")?;
    }
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
    let small = best(&|| phantom::colon(&ColonOptions { small: true, ..ColonOptions::default() }).map(drop).map_err(Into::into))?;
    let full = best(&|| phantom::colon(&ColonOptions::default()).map(drop).map_err(Into::into))?;
    let pipe = best(&|| phantom::pipe(1).map(drop).map_err(Into::into))?;
    println!("{threads} threads: small colon {small:.3} s, full colon {full:.3} s, pipe {pipe:.3} s");
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
    save(&axial(&p.ct, nz / 2), &dir.join(format!("{name}-axial-mid.png")))?;
    save(&coronal(&p.ct, ny / 2), &dir.join(format!("{name}-coronal-mid.png")))?;
    save(&sagittal(&p.ct, nx / 2), &dir.join(format!("{name}-sagittal-mid.png")))?;
    for f in [0.1, 0.3, 0.7, 0.95] {
        let k = ((nz as f64 * f) as usize).min(nz - 1);
        save(&axial(&p.ct, k), &dir.join(format!("{name}-axial-{k:03}.png")))?;
    }
    save(&project(&p.lumen, 1), &dir.join(format!("{name}-lumen-coronal-projection.png")))?;
    save(&project(&p.lumen, 2), &dir.join(format!("{name}-lumen-axial-projection.png")))?;
    // Close-ups (×4) of an axial and a coronal slice through each polyp.
    for (n, pol) in t.polyps.iter().enumerate() {
        let s = p.ct.spacing();
        let [i, j, k] = [0, 1, 2].map(|a| ((pol.center_mm[a] / s[a]).round() as usize).min(p.ct.dims()[a] - 1));
        let ax = crop(&axial(&p.ct, k), i, j, 24);
        let row = ((nz - 1 - k) as f64 * s[2] / s[0]).round() as usize;
        let co = crop(&coronal(&p.ct, j), i, row, 24);
        let tag = format!("{:.0}mm-{}{}", pol.diameter_mm, pol.segment, if pol.behind_fold { "-behind-fold" } else { "" });
        save(&zoom(&ax, 4), &dir.join(format!("{name}-polyp{n}-{tag}-axial.png")))?;
        save(&zoom(&co, 4), &dir.join(format!("{name}-polyp{n}-{tag}-coronal.png")))?;
    }
    Ok(())
}

/// The square of half-size `half` around (cx, cy), clipped to the image.
fn crop(img: &Image, cx: usize, cy: usize, half: usize) -> Image {
    let x0 = cx.saturating_sub(half);
    let y0 = cy.saturating_sub(half);
    let x1 = (cx + half).min(img.w - 1);
    let y1 = (cy + half).min(img.h - 1);
    let px = (y0..=y1).flat_map(|y| (x0..=x1).map(move |x| (x, y))).map(|(x, y)| img.px[x + img.w * y]).collect();
    Image { w: x1 - x0 + 1, h: y1 - y0 + 1, px }
}

/// Nearest-neighbour enlargement.
fn zoom(img: &Image, f: usize) -> Image {
    let (w, h) = (img.w * f, img.h * f);
    let px = (0..h).flat_map(|y| (0..w).map(move |x| (x, y))).map(|(x, y)| img.px[x / f + img.w * (y / f)]).collect();
    Image { w, h, px }
}

/// Abdomen-ish window: −1000 → 0, +400 → 255.
fn window(hu: i16) -> u8 {
    ((hu as f64 + 1000.0) / 1400.0 * 255.0).clamp(0.0, 255.0) as u8
}

/// Axial slice k: patient right (small x) on the left, anterior (small y) on top.
fn axial(ct: &Volume<i16>, k: usize) -> Image {
    let [nx, ny, _] = ct.dims();
    let px = (0..ny).flat_map(|j| (0..nx).map(move |i| (i, j))).map(|(i, j)| window(ct.get(i, j, k))).collect();
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
        (h, (0..h).map(|r| nz - 1 - ((r as f64 * s[0] / s[2]) as usize).min(nz - 1)).collect())
    } else {
        (ny, (0..ny).collect())
    };
    let counts: Vec<usize> = rows.iter().flat_map(|&r| (0..nx).map(move |i| (i, r))).map(|(i, r)| count(i, r)).collect();
    let max = counts.iter().copied().max().unwrap_or(1).max(1) as f64;
    let px = counts.iter().map(|&c| if c == 0 { 0 } else { (50.0 + 205.0 * c as f64 / max) as u8 }).collect();
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
            c = if c & 1 != 0 { 0xEDB8_8320 ^ (c >> 1) } else { c >> 1 };
        }
    }
    !c
}
