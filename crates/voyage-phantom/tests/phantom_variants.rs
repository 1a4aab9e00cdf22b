//! The colon phantom's options that reproduce real CT colonography exams: a prone patient,
//! several collapsed stretches, stretches filled with fluid, opacified small bowel joined to a
//! caecal pool, a rectal catheter, a CT table and skin folds, diverticula, quantised grey
//! levels. Each
//! test fails without its feature; one checks that the phantom without them is bit for bit
//! what it was.
//!
//! Run with `cargo test --release -p voyage-phantom --test phantom_variants`.

use std::{collections::VecDeque, path::PathBuf};

use glam::DVec3;
use voyage_core::Volume;
use voyage_phantom::{self as phantom, ColonOptions, Phantom, SkinFoldTruth, Truth, label};

fn small(opts: ColonOptions) -> Phantom {
    phantom::colon(&ColonOptions {
        small: true,
        ..opts
    })
    .expect("small colon phantom")
}

fn names(list: &[&str]) -> Vec<String> {
    list.iter().map(|s| s.to_string()).collect()
}

// ---------------------------------------------------------------------------------------
// Helpers.

/// FNV-1a (64 bit) over the values' little-endian bytes: stable across platforms and Rust
/// versions.
fn fnv<T: Copy>(data: &[T], bytes: impl Fn(T) -> Vec<u8>) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for &v in data {
        for b in bytes(v) {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    h
}

fn ct_hash(p: &Phantom) -> u64 {
    fnv(p.ct.data(), |v: i16| v.to_le_bytes().to_vec())
}

fn mask_hash(v: &Volume<u8>) -> u64 {
    fnv(v.data(), |x: u8| vec![x])
}

fn local(v: &Volume<u8>, idx: usize) -> [f64; 3] {
    let [i, j, k] = v.geometry().ijk(idx);
    let s = v.spacing();
    [i as f64 * s[0], j as f64 * s[1], k as f64 * s[2]]
}

fn voxel(v: &Volume<u8>, p: [f64; 3]) -> usize {
    let s = v.spacing();
    let d = v.dims();
    let ijk = [0, 1, 2].map(|a| ((p[a] / s[a]).round().max(0.0) as usize).min(d[a] - 1));
    v.geometry().index(ijk[0], ijk[1], ijk[2])
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// The 6-neighbours of voxel `idx`.
fn neighbours6(dims: [usize; 3], idx: usize) -> impl Iterator<Item = usize> {
    let [nx, ny, nz] = dims;
    let (i, j, k) = (idx % nx, (idx / nx) % ny, idx / (nx * ny));
    let plane = nx * ny;
    [
        (i > 0).then(|| idx - 1),
        (i + 1 < nx).then(|| idx + 1),
        (j > 0).then(|| idx - nx),
        (j + 1 < ny).then(|| idx + nx),
        (k > 0).then(|| idx - plane),
        (k + 1 < nz).then(|| idx + plane),
    ]
    .into_iter()
    .flatten()
}

/// Voxels 6-connected to `seeds` through `pass`.
fn flood6(
    dims: [usize; 3],
    seeds: impl IntoIterator<Item = usize>,
    pass: impl Fn(usize) -> bool,
) -> Vec<bool> {
    let mut seen = vec![false; dims[0] * dims[1] * dims[2]];
    let mut queue = VecDeque::new();
    for s in seeds {
        if pass(s) && !seen[s] {
            seen[s] = true;
            queue.push_back(s);
        }
    }
    while let Some(idx) = queue.pop_front() {
        for m in neighbours6(dims, idx) {
            if !seen[m] && pass(m) {
                seen[m] = true;
                queue.push_back(m);
            }
        }
    }
    seen
}

/// Sizes of the 6-connected components of `pass`, largest first.
fn components6(dims: [usize; 3], pass: impl Fn(usize) -> bool) -> Vec<usize> {
    let n = dims[0] * dims[1] * dims[2];
    let mut seen = vec![false; n];
    let mut sizes = Vec::new();
    let mut queue = VecDeque::new();
    for start in 0..n {
        if seen[start] || !pass(start) {
            continue;
        }
        seen[start] = true;
        queue.push_back(start);
        let mut size = 0;
        while let Some(idx) = queue.pop_front() {
            size += 1;
            for m in neighbours6(dims, idx) {
                if !seen[m] && pass(m) {
                    seen[m] = true;
                    queue.push_back(m);
                }
            }
        }
        sizes.push(size);
    }
    sizes.sort_unstable_by(|a, b| b.cmp(a));
    sizes
}

/// The voxels on the rim of an nx × ny slice (indices within the slice).
fn rim2d(nx: usize, ny: usize) -> Vec<usize> {
    (0..nx * ny)
        .filter(|&i| i % nx == 0 || i % nx == nx - 1 || i / nx == 0 || i / nx == ny - 1)
        .collect()
}

/// The border voxels of a volume.
fn border(dims: [usize; 3]) -> Vec<usize> {
    let [nx, ny, nz] = dims;
    (0..nx * ny * nz)
        .filter(|&idx| {
            let (i, j, k) = (idx % nx, (idx / nx) % ny, idx / (nx * ny));
            i == 0 || j == 0 || k == 0 || i == nx - 1 || j == ny - 1 || k == nz - 1
        })
        .collect()
}

/// Arc length of the centerline vertex that holds voxel `x` most deeply (smallest distance
/// minus radius).
fn arc_of(t: &Truth, x: [f64; 3]) -> f64 {
    let (n, _) = t
        .centerline_mm
        .iter()
        .zip(&t.centerline_radius_mm)
        .enumerate()
        .map(|(n, (c, r))| (n, dist(*c, x) - r))
        .fold((0, f64::INFINITY), |b, c| if c.1 < b.1 { c } else { b });
    t.centerline_arc_mm[n]
}

/// What every variant keeps: labels agree with the truth lumen, the true centerline is lumen
/// outside the collapsed stretches and off the catheter, the segments, the polyps.
fn check_basics(p: &Phantom) {
    let t = &p.truth;
    assert_eq!(p.ct.dims(), t.dims);
    for (&l, &m) in p.labels.data().iter().zip(p.lumen.data()) {
        assert_eq!(
            m == 1,
            l == label::LUMEN_AIR
                || l == label::LUMEN_FLUID
                || l == label::STOOL
                || l == label::RECTAL_BALLOON,
            "label {l} vs lumen {m}"
        );
    }
    assert_eq!(
        t.lumen_voxels,
        p.lumen.data().iter().filter(|&&v| v == 1).count()
    );
    let collapsed = |a: f64| {
        t.collapsed
            .iter()
            .any(|c| a > c.start_arc_mm - c.taper_mm && a < c.end_arc_mm + c.taper_mm)
    };
    // A retention balloon's skin crosses the rectum, and the true centerline with it.
    let balloon_skin = |pt: &[f64; 3]| {
        t.rectal_tube
            .as_ref()
            .and_then(|c| c.balloon.as_ref())
            .is_some_and(|b| {
                let reach = b.radius_mm.max(b.half_length_mm) + b.wall_mm;
                dist(*pt, b.center_mm) <= reach + 1.0
                    && p.labels.data()[voxel(&p.lumen, *pt)] == label::WALL
            })
    };
    for (pt, &a) in t.centerline_mm.iter().zip(&t.centerline_arc_mm) {
        if !collapsed(a) && !balloon_skin(pt) {
            assert_eq!(
                p.lumen.data()[voxel(&p.lumen, *pt)],
                1,
                "centerline at arc {a:.1} mm is not lumen"
            );
        }
    }
    for w in t.centerline_mm.windows(2) {
        assert!(dist(w[0], w[1]) <= 1.0 + 1e-9, "centerline has a hole");
    }
    assert_eq!(t.segments.len(), 8);
    assert_eq!(t.segment_at(t.source_arc_mm), Some("rectum"));
    assert_eq!(t.segment_at(t.target_arc_mm), Some("cecum"));
    assert!((6..=10).contains(&t.polyps.len()));
    for q in &t.polyps {
        assert_eq!(
            p.labels.data()[voxel(&p.labels, q.center_mm)],
            label::POLYP,
            "polyp at arc {:.0}",
            q.arc_mm
        );
    }
    // The gaps in the gas are listed in order, each a collapse or a filled stretch.
    assert_eq!(t.gas_gaps.len(), t.collapsed.len() + t.fluid_filled.len());
    assert!(
        t.gas_gaps
            .windows(2)
            .all(|w| w[0].end_arc_mm < w[1].start_arc_mm)
    );
    let back = Truth::from_json(&t.to_json()).expect("truth JSON");
    assert_eq!(back.collapsed.len(), t.collapsed.len());
    assert_eq!(back.position, t.position);
}

// ---------------------------------------------------------------------------------------
// Defaults.

/// The CT, lumen and labels of the phantoms without the new options, hashed before they
/// were added (the CT and lumen also compared byte for byte with files written then).
#[test]
fn phantoms_without_the_new_options_are_unchanged() {
    let p = small(ColonOptions::default());
    assert_eq!(
        ct_hash(&p),
        0xd3e6_da06_4ad7_b82e,
        "default small CT changed"
    );
    assert_eq!(
        mask_hash(&p.lumen),
        0xf400_d7aa_7e9e_7344,
        "default small lumen changed"
    );
    assert_eq!(
        mask_hash(&p.labels),
        0xf427_62a3_d44d_456e,
        "default small labels changed"
    );
    let q = small(ColonOptions {
        tagged_fluid: true,
        collapsed: names(&["descending"]),
        seed: 3,
        ..ColonOptions::default()
    });
    assert_eq!(
        ct_hash(&q),
        0x69b0_ec73_d0a5_ca0e,
        "small CT with fluid and a collapse changed"
    );
    assert_eq!(p.truth.position, "HFS");
    assert_eq!(p.truth.gravity_lps, [0.0, 1.0, 0.0]);
    assert!(
        p.truth.collapsed.is_empty()
            && p.truth.fluid_filled.is_empty()
            && p.truth.gas_gaps.is_empty()
    );
    assert!(
        p.truth.small_bowel_loops.is_empty()
            && p.truth.rectal_tube.is_none()
            && p.truth.body_floor_z_mm.is_none()
    );
}

// ---------------------------------------------------------------------------------------
// Prone.

#[test]
fn prone_fluid_lies_anterior_under_flat_levels() {
    let p = small(ColonOptions {
        tagged_fluid: true,
        prone: true,
        ..ColonOptions::default()
    });
    check_basics(&p);
    let t = &p.truth;
    assert_eq!(t.position, "HFP");
    assert_eq!(t.gravity_lps, [0.0, -1.0, 0.0]);
    assert!(t.fluid_pools.len() >= 2, "{} pools", t.fluid_pools.len());
    let pool_names: Vec<&str> = t.fluid_pools.iter().map(|pl| pl.segment.as_str()).collect();
    assert!(
        pool_names.contains(&"transverse") && pool_names.contains(&"sigmoid"),
        "pools in {pool_names:?}"
    );
    for pl in &t.fluid_pools {
        assert_eq!(pl.gravity_lps, [0.0, -1.0, 0.0]);
    }
    let [nx, ny, nz] = p.ct.dims();
    let sy = p.ct.spacing()[1];
    let mut fluid = 0;
    let mut levels_seen = 0;
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let idx = p.labels.geometry().index(i, j, k);
                let lab = p.labels.data()[idx];
                if lab == label::LUMEN_FLUID {
                    fluid += 1;
                    // On the anterior side (smaller y) of its pool's level.
                    let x = local(&p.labels, idx);
                    let a = arc_of(t, x);
                    let ok = t.fluid_pools.iter().any(|pl| {
                        a >= pl.start_arc_mm - 10.0
                            && a <= pl.end_arc_mm + 10.0
                            && x[1] < pl.level_y_mm
                    });
                    assert!(
                        ok,
                        "fluid at {x:?} (arc {a:.0}) is not anterior of its pool's level"
                    );
                    // Gas never lies under it (anterior, towards the table).
                    assert!(
                        j == 0 || p.labels.get(i, j - 1, k) != label::LUMEN_AIR,
                        "gas under fluid at {i} {j} {k}"
                    );
                    if j + 1 < ny && p.labels.get(i, j + 1, k) == label::LUMEN_AIR {
                        // Gas over fluid: the interface is one of the flat levels.
                        let y = (j as f64 + 0.5) * sy;
                        assert!(
                            t.fluid_pools
                                .iter()
                                .any(|pl| (pl.level_y_mm - y).abs() <= 0.5 * sy + 1e-9),
                            "level at y {y}"
                        );
                        levels_seen += 1;
                    }
                }
            }
        }
    }
    assert!(fluid > 300, "{fluid} fluid voxels");
    assert!(levels_seen > 30, "{levels_seen} level voxels");
    // Supine, the same seed pools posteriorly: the pools are not where the prone ones are.
    let s = small(ColonOptions {
        tagged_fluid: true,
        ..ColonOptions::default()
    });
    assert!(
        s.truth
            .fluid_pools
            .iter()
            .all(|pl| pl.gravity_lps == [0.0, 1.0, 0.0])
    );
    assert_ne!(s.ct.data(), p.ct.data());
}

// ---------------------------------------------------------------------------------------
// Collapses.

#[test]
fn collapses_split_the_gas_and_the_path_runs_through_them() {
    for list in [
        &["sigmoid", "transverse"][..],
        &["sigmoid", "descending", "transverse"][..],
    ] {
        let p = small(ColonOptions {
            collapsed: names(list),
            ..ColonOptions::default()
        });
        check_basics(&p);
        let t = &p.truth;
        assert_eq!(t.collapsed.len(), list.len());
        let gas = components6(p.ct.dims(), |i| p.labels.data()[i] == label::LUMEN_AIR);
        let big: Vec<usize> = gas.iter().copied().filter(|&n| n >= 50).collect();
        assert_eq!(
            big.len(),
            list.len() + 1,
            "{list:?}: gas in {} pieces ({gas:?})",
            big.len()
        );
        assert!(
            gas.iter().skip(big.len()).sum::<usize>() * 1000 < t.lumen_voxels,
            "crumbs of gas: {gas:?}"
        );
        for c in &t.collapsed {
            assert!(list.contains(&c.segment.as_str()));
            assert_eq!(
                t.segment_at(0.5 * (c.start_arc_mm + c.end_arc_mm)),
                Some(c.segment.as_str())
            );
            let len = (c.end_arc_mm - c.start_arc_mm) / t.scale;
            assert!(
                (29.0..=31.0).contains(&len),
                "collapse of {len} mm (full size)"
            );
            assert!(t.gas_gaps.iter().any(|g| g.kind == "collapsed"
                && g.start_arc_mm == c.start_arc_mm
                && g.end_arc_mm == c.end_arc_mm));
            // The true path runs on through the cord: there, no lumen but tissue.
            let inside: Vec<&[f64; 3]> = t
                .centerline_mm
                .iter()
                .zip(&t.centerline_arc_mm)
                .filter(|(_, a)| **a > c.start_arc_mm + 1.0 && **a < c.end_arc_mm - 1.0)
                .map(|(x, _)| x)
                .collect();
            assert!(inside.len() as f64 >= 0.9 * (c.end_arc_mm - c.start_arc_mm - 2.0));
            for x in inside {
                let idx = voxel(&p.lumen, *x);
                assert_eq!(p.lumen.data()[idx], 0);
                assert_eq!(p.labels.data()[idx], label::WALL, "no cord at {x:?}");
            }
        }
    }
}

// ---------------------------------------------------------------------------------------
// Fluid-filled stretches.

#[test]
fn fluid_filled_stretches_hold_no_gas_and_the_lumen_goes_on() {
    let list = ["sigmoid", "transverse", "ascending"];
    let p = small(ColonOptions {
        fluid_filled: names(&list),
        tagged_fluid: true,
        ..ColonOptions::default()
    });
    check_basics(&p);
    let t = &p.truth;
    assert_eq!(t.fluid_filled.len(), 3);
    let sy = p.ct.spacing().iter().cloned().fold(0.0, f64::max);
    for f in &t.fluid_filled {
        let len = (f.end_arc_mm - f.start_arc_mm) / t.scale;
        assert!(
            (40.0..=60.0).contains(&len),
            "filled over {len} mm (full size)"
        );
        assert!((400.0..=700.0).contains(&f.hu));
        assert_eq!(
            t.segment_at(0.5 * (f.start_arc_mm + f.end_arc_mm)),
            Some(f.segment.as_str())
        );
        assert!(
            t.gas_gaps
                .iter()
                .any(|g| g.kind == "fluid_filled" && g.segment == f.segment)
        );
    }
    // Every lumen voxel held by a filled stretch (a voxel in from its ends) is fluid, and
    // the CT there is bright.
    let mut held = 0;
    for (idx, &m) in p.lumen.data().iter().enumerate() {
        if m != 1 {
            continue;
        }
        let a = arc_of(t, local(&p.lumen, idx));
        if t.fluid_filled
            .iter()
            .any(|f| a > f.start_arc_mm + sy && a < f.end_arc_mm - sy)
        {
            held += 1;
            assert_eq!(
                p.labels.data()[idx],
                label::LUMEN_FLUID,
                "gas in a filled stretch at arc {a:.0}"
            );
        }
    }
    assert!(held > 1000, "{held} voxels in the filled stretches");
    for (x, a) in t.centerline_mm.iter().zip(&t.centerline_arc_mm) {
        if t.fluid_filled
            .iter()
            .any(|f| *a > f.start_arc_mm + sy && *a < f.end_arc_mm - sy)
        {
            assert!(
                p.ct.data()[voxel(&p.lumen, *x)] > 300,
                "dark centerline at arc {a:.0}"
            );
        }
    }
    // The gas is split at each stretch; the lumen goes on through it: the true centerline
    // from end to end is in one 6-connected piece of it (which is all of the lumen but for a
    // stray voxel or two at fold crests, as without the option).
    let gas = components6(p.ct.dims(), |i| p.labels.data()[i] == label::LUMEN_AIR);
    let big = gas.iter().filter(|&&n| n >= 50).count();
    assert_eq!(big, list.len() + 1, "gas in {big} pieces ({gas:?})");
    let lumen = components6(p.ct.dims(), |i| p.lumen.data()[i] == 1);
    assert!(lumen[0] + 5 >= t.lumen_voxels, "lumen in pieces: {lumen:?}");
    let source = voxel(&p.lumen, t.source_mm);
    let piece = flood6(p.ct.dims(), [source], |i| p.lumen.data()[i] == 1);
    assert_eq!(piece.iter().filter(|&&v| v).count(), lumen[0]);
    for (x, a) in t.centerline_mm.iter().zip(&t.centerline_arc_mm) {
        assert!(
            piece[voxel(&p.lumen, *x)],
            "centerline at arc {a:.0} cut off from the source"
        );
    }
}

// ---------------------------------------------------------------------------------------
// Opacified small bowel.

fn check_small_bowel(p: &Phantom) {
    check_basics(p);
    let t = &p.truth;
    let dims = p.ct.dims();
    let lab = p.labels.data();
    let ct = p.ct.data();
    let sb: Vec<usize> = (0..lab.len())
        .filter(|&i| lab[i] == label::SMALL_BOWEL_FLUID)
        .collect();
    assert!(sb.len() > 3000, "{} small-bowel voxels", sb.len());
    assert!(
        sb.iter().all(|&i| p.lumen.data()[i] == 0),
        "small bowel in the truth lumen"
    );
    // Loops: ≥ 300 mm (full size) in all, radius 8–12 mm, content 300–600 HU.
    assert!(t.small_bowel_loops.len() >= 2);
    let total: f64 = t.small_bowel_loops.iter().map(|l| l.length_mm).sum();
    assert!(total >= 300.0 * t.scale, "small bowel {total} mm long");
    for l in &t.small_bowel_loops {
        assert!(
            (8.0 * t.scale - 1e-9..=12.0 * t.scale + 1e-9).contains(&l.radius_mm),
            "loop radius {}",
            l.radius_mm
        );
        assert!((300.0..=600.0).contains(&l.hu));
    }
    assert!(t.small_bowel_loops.iter().any(|l| l.enters_cecum));
    assert!(t.small_bowel_loops.iter().any(|l| l.touches_colon));
    assert_eq!(
        t.distractors
            .iter()
            .filter(|d| d.kind == "opacified_small_bowel")
            .count(),
        t.small_bowel_loops.len()
    );
    // The caecal pool: a fluid voxel near the valve, in a pool of the caecum.
    let valve = t.ileocecal_valve_mm.expect("valve");
    assert!(t.fluid_pools.iter().any(|pl| {
        t.segment_at(0.5 * (pl.start_arc_mm + pl.end_arc_mm))
            .is_some()
            && pl.end_arc_mm >= arc_of(t, valve)
    }));
    let pool_voxel = (0..lab.len())
        .filter(|&i| lab[i] == label::LUMEN_FLUID)
        .min_by(|&a, &b| {
            dist(local(&p.labels, a), valve).total_cmp(&dist(local(&p.labels, b), valve))
        })
        .expect("caecal fluid");
    assert!(
        dist(local(&p.labels, pool_voxel), valve) < 3.0 * p.ct.spacing()[0],
        "no caecal fluid at the valve"
    );
    // One bright region: the caecal pool and every loop.
    let bright = flood6(dims, [pool_voxel], |i| ct[i] >= 200);
    let sb_bright: Vec<usize> = sb.iter().copied().filter(|&i| ct[i] >= 200).collect();
    let joined = sb_bright.iter().filter(|&&i| bright[i]).count();
    assert_eq!(
        joined,
        sb_bright.len(),
        "{} of {} bright small-bowel voxels apart from the caecal pool",
        sb_bright.len() - joined,
        sb_bright.len()
    );
    // No gas right above the contrast (against gravity): no level in the small bowel.
    let up: i64 = if t.gravity_lps[1] > 0.0 { -1 } else { 1 };
    let nx = dims[0] as i64;
    for &i in &sb {
        let j = (i / dims[0]) % dims[1];
        if (up < 0 && j == 0) || (up > 0 && j + 1 == dims[1]) {
            continue;
        }
        let above = (i as i64 + up * nx) as usize;
        assert!(
            ct[above] >= -500,
            "gas above small-bowel contrast at {:?}",
            local(&p.labels, i)
        );
    }
    // The loops keep clear of spine, lungs and skin, and meet the colon's lumen only at the
    // valve.
    let r_valve = 3.0
        * t.small_bowel_loops
            .iter()
            .map(|l| l.radius_mm)
            .fold(0.0, f64::max);
    for &i in &sb {
        for m in neighbours6(dims, i) {
            assert!(
                ![label::BONE, label::LUNG, label::OUTSIDE_AIR].contains(&lab[m]),
                "small bowel touches label {}",
                lab[m]
            );
            if p.lumen.data()[m] == 1 {
                assert!(
                    dist(local(&p.labels, i), valve) < r_valve,
                    "small bowel opens into the colon at {:?}",
                    local(&p.labels, i)
                );
            }
        }
    }
}

#[test]
fn opacified_small_bowel_is_one_bright_region_with_the_caecal_pool() {
    for prone in [false, true] {
        let p = small(ColonOptions {
            opacified_small_bowel: true,
            prone,
            ..ColonOptions::default()
        });
        check_small_bowel(&p);
        assert_eq!(
            p.truth.fluid_pools.len(),
            1,
            "only the caecal pool without tagged fluid"
        );
    }
    // Without it: no small-bowel contrast, and the bright region at the caecum (none) is not
    // joined to anything.
    let q = small(ColonOptions::default());
    assert!(
        q.labels
            .data()
            .iter()
            .all(|&l| l != label::SMALL_BOWEL_FLUID)
    );
    assert!(q.truth.ileocecal_valve_mm.is_none());
}

/// The same loops full of gas: small-bowel gas (label 6, air, not colon lumen), one loop
/// against the descending colon, and the terminal ileum's gas one with the caecum's: a flood
/// through gas from the loops' far end reaches the colon's lumen.
#[test]
fn gas_filled_small_bowel_opens_into_the_caecum() {
    for (small_size, prone) in [(true, false), (true, true), (false, false)] {
        let p = phantom::colon(&ColonOptions {
            small: small_size,
            prone,
            gas_filled_small_bowel: true,
            ..ColonOptions::default()
        })
        .unwrap();
        check_basics(&p);
        let t = &p.truth;
        assert_eq!(t.small_bowel_loops.len(), 3);
        assert!(t.small_bowel_loops.iter().all(|l| l.hu < -900.0));
        assert!(t.small_bowel_loops[1].touches_colon && t.small_bowel_loops[2].enters_cecum);
        assert!(!p.labels.data().contains(&label::SMALL_BOWEL_FLUID));
        let far_end = voxel(&p.labels, t.small_bowel_loops[0].axis_mm[0]);
        assert_eq!(p.labels.data()[far_end], label::SMALL_BOWEL_GAS);
        assert_eq!(p.lumen.data()[far_end], 0);
        let gas = flood6(p.labels.dims(), [far_end], |i| p.ct.data()[i] < -500);
        assert!(
            (0..gas.len()).any(|i| gas[i] && p.lumen.data()[i] == 1),
            "small {small_size}, prone {prone}: the loops' gas does not reach the colon's"
        );
    }
    // With the valve closed, the ileum ends short of the caecum: its gas is apart.
    let p = small(ColonOptions {
        gas_filled_small_bowel: true,
        closed_ileocaecal_valve: true,
        ..ColonOptions::default()
    });
    check_basics(&p);
    let t = &p.truth;
    assert!(!t.small_bowel_loops[2].enters_cecum);
    let far_end = voxel(&p.labels, t.small_bowel_loops[0].axis_mm[0]);
    let gas = flood6(p.labels.dims(), [far_end], |i| p.ct.data()[i] < -500);
    assert!(
        (0..gas.len()).all(|i| !gas[i] || p.lumen.data()[i] == 0),
        "the loops' gas reaches the colon's through a closed valve"
    );
}

// ---------------------------------------------------------------------------------------
// Rectal tube.

#[test]
fn rectal_tube_joins_colon_gas_to_the_air_outside() {
    let p = small(ColonOptions {
        rectal_tube: true,
        ..ColonOptions::default()
    });
    check_basics(&p);
    let t = &p.truth;
    let dims = p.ct.dims();
    let (ct, lab) = (p.ct.data(), p.labels.data());
    let tube = t.rectal_tube.as_ref().expect("tube in the truth");
    let floor = t.body_floor_z_mm.expect("a perineum");
    assert!(tube.exit_mm[2] < floor && tube.tip_mm[2] > floor + 10.0 * t.scale);
    assert_eq!(t.segment_at(arc_of(t, tube.tip_mm)), Some("rectum"));
    assert!(
        (2.5 * t.scale..=3.0f64.max(1.8)).contains(&tube.inner_radius_mm),
        "inner radius {}",
        tube.inner_radius_mm
    );
    let air: Vec<usize> = (0..lab.len())
        .filter(|&i| lab[i] == label::RECTAL_TUBE)
        .collect();
    assert!(air.len() > 20, "{} voxels of catheter air", air.len());
    assert!(
        air.iter().all(|&i| p.lumen.data()[i] == 0),
        "catheter air in the truth lumen"
    );
    // From the volume's border through air (CT < −500) into the tube and the colon's gas.
    let outside = flood6(dims, border(dims), |i| ct[i] < -500);
    let colon_gas: Vec<usize> = (0..lab.len())
        .filter(|&i| lab[i] == label::LUMEN_AIR)
        .collect();
    let reached = colon_gas.iter().filter(|&&i| outside[i]).count();
    assert!(
        reached * 100 >= colon_gas.len() * 99,
        "outside air reaches {reached} of {} colon gas voxels",
        colon_gas.len()
    );
    assert!(air.iter().filter(|&&i| ct[i] < -500).all(|&i| outside[i]));
    // Slice by slice inside the body the catheter's air is enclosed by tissue (2D), so only
    // in 3D does it join the outside air; below the perineum there is only outside air.
    let [nx, ny, nz] = dims;
    let sz = p.ct.spacing()[2];
    for k in 0..nz {
        let z = k as f64 * sz;
        let slice: Vec<usize> = (0..nx * ny).map(|i| i + k * nx * ny).collect();
        if z < floor - sz {
            assert!(
                slice.iter().all(|&i| lab[i] == label::OUTSIDE_AIR),
                "body below the perineum at slice {k}"
            );
            continue;
        }
        let tube_here: Vec<usize> = slice
            .iter()
            .copied()
            .filter(|&i| lab[i] == label::RECTAL_TUBE && ct[i] < -500)
            .collect();
        if z < floor + 2.0 * sz || tube_here.is_empty() {
            continue;
        }
        let from_edge = flood6([nx, ny, 1], rim2d(nx, ny), |i| ct[i + k * nx * ny] < -500);
        assert!(
            tube_here.iter().all(|&i| !from_edge[i - k * nx * ny]),
            "catheter air open to the outside within slice {k}"
        );
    }
    // Without the option: no catheter, no perineum, colon gas sealed.
    let q = small(ColonOptions::default());
    let outside = flood6(dims, border(dims), |i| q.ct.data()[i] < -500);
    assert!(
        q.labels
            .data()
            .iter()
            .zip(&outside)
            .all(|(&l, &o)| !(o && l == label::LUMEN_AIR))
    );
}

/// A retention balloon fills the lowest rectum wall to wall, as in a held-out prone exam with
/// a balloon catheter whose centerline started 62 mm from the anus. Its air is lumen (label
/// 12), 15–40 ml at full size; through air alone (CT < −500, the catheter's own air aside)
/// the gas below it (the anal canal's) reaches neither its air nor the rectum's gas above it,
/// and its air does not reach the rectum's gas.
#[test]
fn a_retention_balloon_keeps_the_rectums_gas_apart() {
    let p = phantom::colon(&ColonOptions {
        rectal_tube: true,
        anal_canal: true,
        rectal_balloon: true,
        ..ColonOptions::default()
    })
    .expect("colon phantom with a balloon catheter");
    check_basics(&p);
    let t = &p.truth;
    let b = t
        .rectal_tube
        .as_ref()
        .and_then(|c| c.balloon.as_ref())
        .expect("the balloon in the truth");
    let (ct, lab, dims) = (p.ct.data(), p.labels.data(), p.ct.dims());
    let ml = p.ct.spacing().iter().product::<f64>() / 1000.0;
    let balloon: Vec<usize> = (0..lab.len())
        .filter(|&i| lab[i] == label::RECTAL_BALLOON)
        .collect();
    let volume = balloon.len() as f64 * ml;
    assert!((15.0..=40.0).contains(&volume), "balloon {volume:.1} ml");
    assert!(balloon.iter().all(|&i| p.lumen.data()[i] == 1));
    let gas = |i: usize| ct[i] < -500 && lab[i] != label::RECTAL_TUBE;
    let bottom = b.center_mm[2] - b.half_length_mm - b.wall_mm;
    let below: Vec<usize> = (0..lab.len())
        .filter(|&i| lab[i] == label::LUMEN_AIR && local(&p.lumen, i)[2] < bottom - 2.0)
        .collect();
    assert!(
        below.len() > 100,
        "{} voxels of gas below the balloon",
        below.len()
    );
    let above = voxel(
        &p.lumen,
        t.centerline_mm[t.centerline_arc_mm.partition_point(|&a| a < 100.0)],
    );
    assert_eq!(lab[above], label::LUMEN_AIR);
    let from_below = flood6(dims, below.iter().copied(), gas);
    assert!(
        !from_below[above],
        "the canal's gas reaches the rectum's above the balloon"
    );
    assert!(
        balloon.iter().all(|&i| !from_below[i]),
        "the canal's gas reaches the balloon's"
    );
    let from_balloon = flood6(dims, balloon.iter().copied(), gas);
    assert!(
        !from_balloon[above],
        "the balloon's air reaches the rectum's gas"
    );
}

// ---------------------------------------------------------------------------------------
// Table and skin folds.

fn v3(a: [f64; 3]) -> DVec3 {
    DVec3::from_array(a)
}

/// A point of fold `f` at depth `u`, `l` along it (its mid-plane).
fn fold_point(f: &SkinFoldTruth, u: f64, l: f64) -> [f64; 3] {
    (v3(f.mouth_mm) + v3(f.inward) * u + v3(f.along) * l).to_array()
}

/// Whether voxel `idx` lies in a fold's air by the truth's geometry.
fn in_fold(f: &SkinFoldTruth, v: &Volume<u8>, idx: usize) -> bool {
    let d = v3(local(v, idx)) - v3(f.mouth_mm);
    let (inward, along) = (v3(f.inward), v3(f.along));
    let (u, l, w) = (d.dot(inward), d.dot(along), d.dot(inward.cross(along)));
    w.abs() <= 0.5 * f.width_mm
        && (0.0..=f.depth_mm).contains(&u)
        && (f.span_mm[0]..=f.span_mm[1]).contains(&l)
}

/// On the table with skin folds, prone with a catheter and supine without: the table under
/// the body on the dependent side in every slice (a bright shell round dark foam, not the
/// patient), the skin flat on it over the contact strip with a wedge of outside air beside
/// it; 4–8 folds of outside air, 3–6 beside the table and 1–2 low in the scan, some enclosed
/// in axial slices, all joined to the outside air in 3D; the truth lumen as without them.
#[test]
fn table_and_skin_folds_lie_at_the_skin() {
    for prone in [true, false] {
        let opts = ColonOptions {
            prone,
            rectal_tube: prone,
            tagged_fluid: true,
            ..ColonOptions::default()
        };
        let p = small(ColonOptions {
            table: true,
            skin_folds: true,
            ..opts.clone()
        });
        let plain = small(opts);
        check_basics(&p);
        assert!(
            p.lumen.data() == plain.lumen.data(),
            "prone {prone}: the truth lumen changed"
        );
        check_table(&p, prone);
        check_folds_air(&p, prone);
    }
}

fn check_table(p: &Phantom, prone: bool) {
    let t = &p.truth;
    let table = t.table.as_ref().expect("a table in the truth");
    assert_eq!(table.side, if prone { "anterior" } else { "posterior" });
    let [nx, ny, nz] = p.ct.dims();
    let s = p.ct.spacing();
    let (ct, lab) = (p.ct.data(), p.labels.data());
    let down = (table.bottom_y_mm - table.top_y_mm).signum();
    let row = |y: f64| ((y / s[1]).round() as usize).min(ny - 1);
    let col = |x: f64| ((x / s[0]).round().max(0.0) as usize).min(nx - 1);
    let at = |i: usize, j: usize, k: usize| i + nx * (j + ny * k);
    // Wider than the field of view, as on a real exam.
    assert!(table.x_range_mm[0] < 0.0 && table.x_range_mm[1] > (nx - 1) as f64 * s[0]);
    let mid_x = 0.5 * (table.contact_x_mm[0] + table.contact_x_mm[1]);
    let foam_row = row(0.5 * (table.top_y_mm + table.bottom_y_mm));
    // Beside the contact strip, where the skin has left the table by ≥ 2 voxels.
    let beside = col(table.contact_x_mm[1] + 25.0 * t.scale);
    let mut foam = Vec::new();
    for k in 0..nz {
        for i in 0..nx {
            foam.push(ct[at(i, foam_row, k)]);
            assert_eq!(
                lab[at(i, foam_row, k)],
                label::OTHER,
                "the table is not other"
            );
        }
        // Through the shell: a bright voxel between foam and the top.
        let shell = (0..=4)
            .map(|d| row(table.top_y_mm + down * d as f64 * s[1]))
            .map(|j| ct[at(col(mid_x), j, k)])
            .max()
            .unwrap_or(i16::MIN);
        assert!(
            shell > 100,
            "slice {k}: no shell under the body ({shell} HU)"
        );
        if t.body_floor_z_mm
            .is_some_and(|f| (k as f64 * s[2]) < f + 2.0 * s[2])
        {
            continue;
        }
        // The body rests on the table over the contact strip...
        let skin = row(table.top_y_mm - down * s[1]);
        assert_ne!(
            lab[at(col(mid_x), skin, k)],
            label::OUTSIDE_AIR,
            "slice {k}: the body does not rest on the table"
        );
        // ...and beside it outside air lies between skin and table.
        assert_eq!(
            lab[at(beside, skin, k)],
            label::OUTSIDE_AIR,
            "slice {k}: no air between skin and table beside the contact"
        );
    }
    foam.sort_unstable();
    let median = foam[foam.len() / 2] as f64;
    assert!(
        (median - table.foam_hu).abs() < 10.0,
        "foam median {median} HU, made of {} HU",
        table.foam_hu
    );
}

fn check_folds_air(p: &Phantom, prone: bool) {
    let t = &p.truth;
    let folds = &t.skin_folds;
    let count = |r: &str| folds.iter().filter(|f| f.region == r).count();
    let low = if prone { "perineal" } else { "gluteal" };
    assert!(
        (4..=8).contains(&folds.len())
            && (3..=6).contains(&count("dependent"))
            && (1..=2).contains(&count(low)),
        "prone {prone}: folds {:?}",
        folds.iter().map(|f| &f.region).collect::<Vec<_>>()
    );
    assert!(folds.iter().any(|f| f.closed_mm.is_some()));
    let dims = p.ct.dims();
    let (ct, lab) = (p.ct.data(), p.labels.data());
    // Deep in each fold, where it is not closed over: outside air.
    for f in folds {
        let l = match f.closed_mm {
            Some([a, _]) if a > f.span_mm[0] => 0.5 * (f.span_mm[0] + a),
            Some([_, b]) => 0.5 * (b + f.span_mm[1]),
            None => 0.5 * (f.span_mm[0] + f.span_mm[1]),
        };
        let deep = voxel(&p.labels, fold_point(f, 0.6 * f.depth_mm, l));
        assert_eq!(
            lab[deep],
            label::OUTSIDE_AIR,
            "prone {prone}: a {} fold's air is not outside air",
            f.region
        );
    }
    let air: Vec<usize> = (0..lab.len())
        .filter(|&i| ct[i] < -500 && folds.iter().any(|f| in_fold(f, &p.labels, i)))
        .collect();
    assert!(
        air.iter()
            .all(|&i| lab[i] == label::OUTSIDE_AIR && p.lumen.data()[i] == 0)
    );
    // In some axial slices a fold's air is enclosed in the body...
    let [nx, ny, nz] = dims;
    let mut enclosed = 0;
    for k in 0..nz {
        let from_edge = flood6([nx, ny, 1], rim2d(nx, ny), |i| ct[i + k * nx * ny] < -500);
        enclosed += air
            .iter()
            .filter(|&&i| i / (nx * ny) == k && !from_edge[i % (nx * ny)])
            .count();
    }
    assert!(
        enclosed > 0,
        "prone {prone}: no fold air enclosed in a slice"
    );
    // ...yet every fold is outside air in 3D. An oblique slit one or two voxels wide breaks
    // up under the threshold into pieces that touch only at edges, so not every voxel is
    // 6-connected to the rest.
    let outside = flood6(dims, border(dims), |i| ct[i] < -500);
    for f in folds {
        assert!(
            air.iter().any(|&i| outside[i] && in_fold(f, &p.labels, i)),
            "prone {prone}: a {} fold's air is not joined to the outside",
            f.region
        );
    }
    let joined = air.iter().filter(|&&i| outside[i]).count();
    assert!(
        joined * 100 >= air.len() * 80,
        "prone {prone}: {joined} of {} fold air voxels joined to the outside",
        air.len()
    );
}

// ---------------------------------------------------------------------------------------
// Quantisation.

/// Tagged stool: two lumps in each segment from the rectum to the ascending colon, bright,
/// inside the lumen and on its wall, one of each two mottled with air; in the truth.
#[test]
fn tagged_stool_lies_on_the_wall_as_bright_lumen() {
    for small_size in [true, false] {
        let p = phantom::colon(&ColonOptions {
            small: small_size,
            tagged_fluid: true,
            tagged_stool: true,
            ..Default::default()
        })
        .unwrap();
        check_basics(&p);
        let t = &p.truth;
        assert_eq!(t.stool.len(), 10);
        let dims = p.labels.dims();
        for s in &t.stool {
            let v = voxel(&p.labels, s.center_mm);
            assert_eq!(
                p.labels.data()[v],
                label::STOOL,
                "stool in the {} at its centre",
                s.segment
            );
            // The lump's voxels: bright (or, mottled, some of them air), and some touch the wall.
            let lump = flood6(dims, [v], |i| p.labels.data()[i] == label::STOOL);
            let voxels: Vec<usize> = (0..lump.len()).filter(|&i| lump[i]).collect();
            let bright = voxels.iter().filter(|&&i| p.ct.data()[i] >= 300).count();
            let air = voxels.iter().filter(|&&i| p.ct.data()[i] < -500).count();
            assert!(
                bright * 3 >= voxels.len(),
                "stool in the {}: {bright} of {} voxels bright",
                s.segment,
                voxels.len()
            );
            assert!(
                !s.mottled || small_size || air > 0,
                "stool in the {}: {air} voxels of air, mottled {}",
                s.segment,
                s.mottled
            );
            assert!(
                s.mottled || air == 0,
                "stool in the {}: {air} voxels of air, not mottled",
                s.segment
            );
            assert!(
                voxels
                    .iter()
                    .any(|&i| neighbours6(dims, i).any(|n| p.labels.data()[n] == label::WALL)),
                "stool in the {} does not touch the wall",
                s.segment
            );
        }
        assert_eq!(Truth::from_json(&t.to_json()).unwrap().stool, t.stool);
    }
}

/// Each diverticulum is a pouch of the colon's gas (lumen, air) outside the colon's wall,
/// beyond the tube the truth's centerline and radius draw, joined through the wall to the
/// colon's lumen: a flood of the lumen from the pouch's centre, kept to the pouch and a few
/// mm round it, reaches the colon's own lumen.
#[test]
fn diverticula_are_pouches_of_gas_joined_through_the_wall() {
    for (small_size, prone) in [(true, false), (false, false), (false, true)] {
        let p = phantom::colon(&ColonOptions {
            small: small_size,
            prone,
            diverticula: true,
            tagged_fluid: true,
            ..Default::default()
        })
        .unwrap();
        check_basics(&p);
        let t = &p.truth;
        assert_eq!(t.diverticula.len(), 10);
        let dims = p.labels.dims();
        // How far a point lies beyond the colon's nominal lumen (negative: inside it).
        let beyond = |x: [f64; 3]| {
            t.centerline_mm
                .iter()
                .zip(&t.centerline_radius_mm)
                .map(|(c, r)| dist(*c, x) - r)
                .fold(f64::INFINITY, f64::min)
        };
        for d in &t.diverticula {
            let v = voxel(&p.labels, d.center_mm);
            assert_eq!(
                (p.labels.data()[v], p.lumen.data()[v]),
                (label::LUMEN_AIR, 1),
                "diverticulum in the {} at its centre",
                d.segment
            );
            assert!(p.ct.data()[v] < -800, "{} HU", p.ct.data()[v]);
            assert!(
                beyond(d.center_mm) > t.wall_thickness_mm,
                "the diverticulum in the {} at {:.0} mm lies inside the wall",
                d.segment,
                d.arc_mm
            );
            let near = |i: usize| dist(local(&p.lumen, i), d.center_mm) <= 2.0 * d.radius_mm + 3.0;
            let reached = flood6(dims, [v], |i| p.lumen.data()[i] == 1 && near(i));
            let joined =
                (0..reached.len()).any(|i| reached[i] && beyond(local(&p.lumen, i)) < -1.0);
            assert!(
                joined,
                "the diverticulum in the {} at {:.0} mm is not joined to the lumen",
                d.segment, d.arc_mm
            );
        }
        assert_eq!(
            Truth::from_json(&t.to_json()).unwrap().diverticula,
            t.diverticula
        );
    }
}

#[test]
fn quantised_ct_takes_multiples_of_the_step() {
    let p = small(ColonOptions {
        quantize_hu: Some(8.0),
        tagged_fluid: true,
        ..ColonOptions::default()
    });
    assert!(
        p.ct.data().iter().all(|&v| v % 8 == 0),
        "a value off the grid"
    );
    assert_eq!(p.truth.quantize_hu, Some(8.0));
    let plain = small(ColonOptions {
        tagged_fluid: true,
        ..ColonOptions::default()
    });
    assert!(plain.ct.data().iter().any(|&v| v % 8 != 0));
    // Same anatomy: each value is the plain one's, rounded (±½ step and the rounding of the
    // unrounded noise).
    assert!(
        p.ct.data()
            .iter()
            .zip(plain.ct.data())
            .all(|(&a, &b)| (a as i32 - b as i32).abs() <= 5)
    );
    for bad in [0.0, -4.0, f64::NAN, f64::INFINITY] {
        let e = phantom::colon(&ColonOptions {
            small: true,
            quantize_hu: Some(bad),
            ..ColonOptions::default()
        })
        .unwrap_err();
        assert!(e.to_string().contains("quantisation step"), "{e}");
    }
}

// ---------------------------------------------------------------------------------------
// Everything at once, and bad names.

/// Every new option at once (full size unless `small` is set).
fn every_option(seed: u64) -> ColonOptions {
    ColonOptions {
        seed,
        prone: true,
        tagged_fluid: true,
        opacified_small_bowel: true,
        collapsed: names(&["sigmoid", "descending"]),
        fluid_filled: names(&["transverse"]),
        rectal_tube: true,
        rectal_balloon: true,
        table: true,
        skin_folds: true,
        diverticula: true,
        quantize_hu: Some(8.0),
        ..ColonOptions::default()
    }
}

#[test]
fn all_options_combine_for_several_seeds() {
    for seed in 1..=5 {
        let p = small(every_option(seed));
        check_small_bowel(&p);
        assert!(p.ct.data().iter().all(|&v| v % 8 == 0));
        assert_eq!(p.truth.gas_gaps.len(), 3);
        assert!(p.labels.data().contains(&label::RECTAL_TUBE));
    }
    // Also at full size (one seed): the same checks of the truth.
    let p = phantom::colon(&every_option(1)).expect("full-size phantom with every option");
    check_basics(&p);
    assert!(p.labels.data().contains(&label::SMALL_BOWEL_FLUID));
}

#[test]
fn every_option_is_deterministic_whatever_the_threads() {
    let opts = ColonOptions {
        small: true,
        seed: 4,
        tagged_fluid: true,
        opacified_small_bowel: true,
        collapsed: names(&["transverse"]),
        fluid_filled: names(&["descending"]),
        rectal_tube: true,
        rectal_balloon: true,
        table: true,
        skin_folds: true,
        diverticula: true,
        quantize_hu: Some(4.0),
        ..ColonOptions::default()
    };
    let a = phantom::colon(&opts).expect("colon");
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    let b = pool.install(|| phantom::colon(&opts)).expect("colon");
    assert!(
        a.ct.data() == b.ct.data()
            && a.labels.data() == b.labels.data()
            && a.lumen.data() == b.lumen.data()
    );
    assert_eq!(a.truth, b.truth);
    let c = phantom::colon(&ColonOptions { seed: 5, ..opts }).expect("colon");
    assert_ne!(
        a.truth.small_bowel_loops, c.truth.small_bowel_loops,
        "the loops do not depend on the seed"
    );
}

#[test]
fn older_truth_files_still_read() {
    let p = small(ColonOptions {
        collapsed: names(&["descending"]),
        ..ColonOptions::default()
    });
    let mut v: serde_json::Value = serde_json::from_str(&p.truth.to_json()).expect("json");
    let obj = v.as_object_mut().expect("object");
    // Before: one collapse or null, no position, gravity, gaps, loops or tube.
    let one = obj["collapsed"][0].clone();
    for key in [
        "position",
        "gravity_lps",
        "quantize_hu",
        "fluid_filled",
        "gas_gaps",
        "small_bowel_loops",
        "ileocecal_valve_mm",
        "rectal_tube",
        "body_floor_z_mm",
        "table",
        "skin_folds",
    ] {
        obj.remove(key);
    }
    obj.insert("collapsed".into(), one);
    let back = Truth::from_json(&v.to_string()).expect("older truth");
    assert_eq!(back.collapsed.len(), 1);
    assert_eq!(
        (back.position.as_str(), back.gravity_lps),
        ("HFS", [0.0, 1.0, 0.0])
    );
    v.as_object_mut()
        .expect("object")
        .insert("collapsed".into(), serde_json::Value::Null);
    assert!(
        Truth::from_json(&v.to_string())
            .expect("older truth")
            .collapsed
            .is_empty()
    );
}

#[test]
fn unknown_or_repeated_segments_are_refused() {
    let e = |o: ColonOptions| {
        phantom::colon(&ColonOptions { small: true, ..o })
            .unwrap_err()
            .to_string()
    };
    assert!(
        e(ColonOptions {
            collapsed: names(&["cecum"]),
            ..ColonOptions::default()
        })
        .contains("choose from sigmoid, descending, transverse")
    );
    assert!(
        e(ColonOptions {
            collapsed: names(&["sigmoid", "sigmoid"]),
            ..ColonOptions::default()
        })
        .contains("named twice")
    );
    assert!(
        e(ColonOptions {
            fluid_filled: names(&["appendix"]),
            ..ColonOptions::default()
        })
        .contains("fluid-filled segment 'appendix'")
    );
    assert!(
        e(ColonOptions {
            opacified_small_bowel: true,
            gas_filled_small_bowel: true,
            ..ColonOptions::default()
        })
        .contains("contrast or gas, not both")
    );
}

// ---------------------------------------------------------------------------------------
// DICOM.

#[test]
fn dicom_of_a_prone_phantom_says_hfp() {
    use dicom_dictionary_std::tags;
    use voyage_io::dicom_write::{SeriesWriteOptions, write_series_with};
    let p = small(ColonOptions {
        prone: true,
        tagged_fluid: true,
        ..ColonOptions::default()
    });
    let dir: PathBuf =
        std::env::temp_dir().join(format!("voyage-phantom-prone-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let opts = SeriesWriteOptions {
        patient_position: Some(p.truth.position.clone()),
        ..Default::default()
    };
    write_series_with(&dir, &p.ct, &opts).expect("write");
    let obj = dicom_object::open_file(dir.join("slice0010.dcm")).expect("read back");
    let position = obj
        .element(tags::PATIENT_POSITION)
        .expect("PatientPosition")
        .to_str()
        .expect("text")
        .trim()
        .to_string();
    assert_eq!(position, "HFP");
    // The default options leave the element out.
    write_series_with(&dir, &p.ct, &SeriesWriteOptions::default()).expect("write");
    let obj = dicom_object::open_file(dir.join("slice0010.dcm")).expect("read back");
    assert!(obj.element(tags::PATIENT_POSITION).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}
