//! The phantoms are the ground truth of every later test, so these tests check that the
//! voxels say what the truth says: centerline inside the lumen, polyps where and how big
//! the truth says, one lumen not touching the border, distractors not in the lumen,
//! noise of the stated size, determinism across thread counts.
//!
//! Run with `cargo test --release -p voyage-phantom --test phantom`.

use std::{collections::VecDeque, sync::OnceLock};

use voyage_core::Volume;
use voyage_phantom::{self as phantom, ColonOptions, Phantom, Truth, label};

// ---------------------------------------------------------------------------------------
// Shared phantoms (made once per test binary).

fn pipe() -> &'static Phantom {
    static P: OnceLock<Phantom> = OnceLock::new();
    P.get_or_init(|| phantom::pipe(7).expect("pipe phantom"))
}

fn small(opts: ColonOptions) -> Phantom {
    phantom::colon(&ColonOptions {
        small: true,
        ..opts
    })
    .expect("small colon phantom")
}

fn small_default() -> &'static Phantom {
    static P: OnceLock<Phantom> = OnceLock::new();
    P.get_or_init(|| small(ColonOptions::default()))
}

// ---------------------------------------------------------------------------------------
// Helpers.

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Nearest voxel to a point in volume-local mm, if inside the grid.
fn voxel_of<T: Copy>(v: &Volume<T>, p: [f64; 3]) -> Option<[usize; 3]> {
    let s = v.spacing();
    let d = v.dims();
    let mut ijk = [0usize; 3];
    for a in 0..3 {
        let x = (p[a] / s[a]).round();
        if x < 0.0 || x > (d[a] - 1) as f64 {
            return None;
        }
        ijk[a] = x as usize;
    }
    Some(ijk)
}

fn at<T: Copy>(v: &Volume<T>, p: [f64; 3]) -> T {
    let [i, j, k] = voxel_of(v, p).unwrap_or_else(|| panic!("{p:?} outside the volume"));
    v.get(i, j, k)
}

fn local(v: &Volume<u8>, idx: usize) -> [f64; 3] {
    let [i, j, k] = v.geometry().ijk(idx);
    let s = v.spacing();
    [i as f64 * s[0], j as f64 * s[1], k as f64 * s[2]]
}

/// Connected components (26-neighbourhood) of `mask`: (size, touches the border, a voxel).
fn components(v: &Volume<u8>, inside: impl Fn(usize) -> bool) -> Vec<(usize, bool, usize)> {
    let [nx, ny, nz] = v.dims();
    let n = nx * ny * nz;
    let mut seen = vec![false; n];
    let mut out = Vec::new();
    let mut queue = VecDeque::new();
    for start in 0..n {
        if seen[start] || !inside(start) {
            continue;
        }
        seen[start] = true;
        queue.push_back(start);
        let (mut size, mut border) = (0usize, false);
        while let Some(idx) = queue.pop_front() {
            size += 1;
            let [i, j, k] = v.geometry().ijk(idx);
            border |= i == 0 || j == 0 || k == 0 || i == nx - 1 || j == ny - 1 || k == nz - 1;
            for dk in -1i64..=1 {
                for dj in -1i64..=1 {
                    for di in -1i64..=1 {
                        let (a, b, c) = (i as i64 + di, j as i64 + dj, k as i64 + dk);
                        if a < 0
                            || b < 0
                            || c < 0
                            || a >= nx as i64
                            || b >= ny as i64
                            || c >= nz as i64
                        {
                            continue;
                        }
                        let m = a as usize + nx * (b as usize + ny * c as usize);
                        if !seen[m] && inside(m) {
                            seen[m] = true;
                            queue.push_back(m);
                        }
                    }
                }
            }
        }
        out.push((size, border, start));
    }
    out
}

/// Lumen voxels 26-connected to `start`.
fn flood_from(v: &Volume<u8>, start: usize) -> Vec<bool> {
    let [nx, ny, nz] = v.dims();
    let mut seen = vec![false; nx * ny * nz];
    let mut stack = vec![start];
    seen[start] = true;
    while let Some(idx) = stack.pop() {
        let [i, j, k] = v.geometry().ijk(idx);
        for dk in -1i64..=1 {
            for dj in -1i64..=1 {
                for di in -1i64..=1 {
                    let (a, b, c) = (i as i64 + di, j as i64 + dj, k as i64 + dk);
                    if a < 0 || b < 0 || c < 0 || a >= nx as i64 || b >= ny as i64 || c >= nz as i64
                    {
                        continue;
                    }
                    let m = a as usize + nx * (b as usize + ny * c as usize);
                    if !seen[m] && v.data()[m] == 1 {
                        seen[m] = true;
                        stack.push(m);
                    }
                }
            }
        }
    }
    seen
}

/// Voxels reached from the volume border through `pass` (6-neighbourhood).
fn flood_from_border(dims: [usize; 3], pass: impl Fn(usize) -> bool) -> Vec<bool> {
    let [nx, ny, nz] = dims;
    let mut seen = vec![false; nx * ny * nz];
    let mut stack = Vec::new();
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                if i == 0 || j == 0 || k == 0 || i == nx - 1 || j == ny - 1 || k == nz - 1 {
                    let idx = i + nx * (j + ny * k);
                    if pass(idx) {
                        seen[idx] = true;
                        stack.push(idx);
                    }
                }
            }
        }
    }
    while let Some(idx) = stack.pop() {
        let (i, j, k) = (idx % nx, (idx / nx) % ny, idx / (nx * ny));
        let mut visit = |m: usize| {
            if !seen[m] && pass(m) {
                seen[m] = true;
                stack.push(m);
            }
        };
        if i > 0 {
            visit(idx - 1);
        }
        if i + 1 < nx {
            visit(idx + 1);
        }
        if j > 0 {
            visit(idx - nx);
        }
        if j + 1 < ny {
            visit(idx + nx);
        }
        if k > 0 {
            visit(idx - nx * ny);
        }
        if k + 1 < nz {
            visit(idx + nx * ny);
        }
    }
    seen
}

/// Mean and standard deviation of the CT inside a truth ROI.
fn roi_stats(p: &Phantom) -> (f64, f64) {
    let roi = p.truth.noise_roi.as_ref().expect("noise ROI");
    let mut v = Vec::new();
    for k in roi.min_ijk[2]..=roi.max_ijk[2] {
        for j in roi.min_ijk[1]..=roi.max_ijk[1] {
            for i in roi.min_ijk[0]..=roi.max_ijk[0] {
                v.push(p.ct.get(i, j, k) as f64);
            }
        }
    }
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (v.len() - 1) as f64;
    (mean, var.sqrt())
}

fn arc_point(t: &Truth, s: f64) -> [f64; 3] {
    let i = t
        .centerline_arc_mm
        .partition_point(|&a| a < s)
        .min(t.centerline_mm.len() - 1);
    t.centerline_mm[i]
}

/// Checks shared by every colon: truth consistent with itself and with the voxels.
fn check_colon(p: &Phantom, collapsed: bool) {
    let t = &p.truth;
    let s = t.scale;
    assert_eq!(t.kind, "colon");
    assert_eq!(p.ct.dims(), t.dims);
    assert_eq!(p.lumen.dims(), t.dims);
    // Length and radii.
    assert!(
        (1300.0 * s..=1700.0 * s).contains(&t.centerline_length_mm),
        "length {}",
        t.centerline_length_mm
    );
    assert!(
        t.centerline_radius_mm
            .iter()
            .all(|r| (10.0 * s - 1e-9..=30.0 * s + 1e-9).contains(r))
    );
    let rmax = t.centerline_radius_mm.iter().cloned().fold(0.0, f64::max);
    let rmin = t
        .centerline_radius_mm
        .iter()
        .cloned()
        .fold(f64::INFINITY, f64::min);
    assert!(rmax >= 27.0 * s && rmin <= 13.0 * s, "radii {rmin}..{rmax}");
    // Dense centerline, arc lengths consistent.
    for w in t.centerline_mm.windows(2) {
        assert!(dist(w[0], w[1]) <= 1.0 + 1e-9);
    }
    assert!(
        (t.centerline_arc_mm.last().copied().unwrap_or(0.0) - t.centerline_length_mm).abs() < 1e-6
    );
    // Different parts of the colon keep ≥ 6 mm (scaled) of tissue between them.
    assert!(
        t.min_part_gap_mm >= 6.0 * s,
        "loops {} mm apart",
        t.min_part_gap_mm
    );
    // Segments in anatomical order, covering the centerline.
    let names: Vec<&str> = t.segments.iter().map(|g| g.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "rectum",
            "sigmoid",
            "descending",
            "splenic_flexure",
            "transverse",
            "hepatic_flexure",
            "ascending",
            "cecum"
        ]
    );
    assert_eq!(t.segments[0].start_arc_mm, 0.0);
    for w in t.segments.windows(2) {
        assert_eq!(w[0].end_arc_mm, w[1].start_arc_mm);
    }
    assert!(
        (t.segments.last().map_or(0.0, |g| g.end_arc_mm) - t.centerline_length_mm).abs() < 1e-9
    );
    // Every centerline point is lumen (except where the colon is collapsed).
    let skip = |a: f64| {
        collapsed
            && t.collapsed
                .iter()
                .any(|c| a > c.start_arc_mm - c.taper_mm && a < c.end_arc_mm + c.taper_mm)
    };
    for (pt, &a) in t.centerline_mm.iter().zip(&t.centerline_arc_mm) {
        if !skip(a) {
            assert_eq!(
                at(&p.lumen, *pt),
                1,
                "centerline at arc {a:.1} mm {pt:?} is not lumen"
            );
        }
    }
    check_folds(p);
    check_polyps(p);
    // Source in the rectum: low, midline, posterior; target in the cecum: low-ish, right.
    let ext = [0, 1, 2].map(|a| (t.dims[a] - 1) as f64 * t.spacing_mm[a]);
    assert_eq!(t.segment_at(t.source_arc_mm), Some("rectum"));
    assert_eq!(t.segment_at(t.target_arc_mm), Some("cecum"));
    assert!(t.source_mm[2] < 0.2 * ext[2], "source {:?}", t.source_mm);
    assert!(
        (t.source_mm[0] - 0.5 * ext[0]).abs() < 0.05 * ext[0],
        "source {:?}",
        t.source_mm
    );
    assert!(
        t.source_mm[1] > 0.5 * ext[1],
        "source not posterior: {:?}",
        t.source_mm
    );
    assert!(
        t.target_mm[0] < 0.35 * ext[0],
        "target not on the right: {:?}",
        t.target_mm
    );
    assert!(
        t.target_mm[2] < 0.5 * ext[2],
        "target not low: {:?}",
        t.target_mm
    );
    assert!((dist(t.source_mm, t.centerline_mm[0]) - 15.0 * s).abs() < 1.0);
    assert_eq!(
        t.lumen_voxels,
        p.lumen.data().iter().filter(|&&v| v == 1).count()
    );
    // Labels agree with the mask.
    for (&l, &m) in p.labels.data().iter().zip(p.lumen.data()) {
        assert_eq!(m == 1, l == label::LUMEN_AIR || l == label::LUMEN_FLUID);
    }
}

/// 20–30 mm apart (scaled), none in the rectum, and actually there in the voxels.
fn check_folds(p: &Phantom) {
    let t = &p.truth;
    let s = t.scale;
    assert_eq!(t.folds, t.fold_list.len());
    assert!(t.folds >= 40, "only {} folds", t.folds);
    assert!(
        t.fold_list
            .iter()
            .all(|f| f.segment != "rectum" && !f.segment.is_empty())
    );
    let gaps_ok = t.fold_list.windows(2).filter(|w| {
        let gap = w[1].arc_mm - w[0].arc_mm;
        (20.0 * s - 1e-9..=30.0 * s + 1e-9).contains(&gap)
    });
    // Only a collapsed stretch may leave a longer gap (one per collapse).
    let allowed = t.collapsed.len();
    assert!(
        gaps_ok.count() + allowed >= t.folds - 1,
        "fold spacing outside 20–30 mm"
    );
    for f in &t.fold_list {
        assert!(
            f.depth_mm
                .iter()
                .all(|&d| (3.0 * s - 1e-9..=8.0 * s + 1e-9).contains(&d)),
            "fold depth {:?}",
            f.depth_mm
        );
    }
    // The deepest crescent of (nearly) every fold is tissue halfway up its depth.
    let mut present = 0;
    for f in &t.fold_list {
        let k = (0..3)
            .max_by(|&a, &b| f.depth_mm[a].total_cmp(&f.depth_mm[b]))
            .unwrap_or(0);
        let arc = f.arc_mm + f.offset_mm[k];
        let angle = f.phase_rad + (k as f64 + 0.5) * std::f64::consts::TAU / 3.0;
        let (q, dir) = radial(t, arc, angle);
        let r = t.centerline_radius_mm[t
            .centerline_arc_mm
            .partition_point(|&a| a < arc)
            .min(t.centerline_mm.len() - 1)];
        let probe = [0, 1, 2].map(|a| q[a] + dir[a] * (r - 0.4 * f.depth_mm[k]));
        if at(&p.lumen, probe) == 0 {
            present += 1;
        }
    }
    assert!(
        present * 10 >= t.folds * 9,
        "only {present} of {} folds show in the voxels",
        t.folds
    );
}

/// Point on the centerline at `arc` and the unit vector at frame angle `angle`, rebuilding
/// the rotation-minimising frame from the polyline the same way the generator does.
fn radial(t: &Truth, arc: f64, angle: f64) -> ([f64; 3], [f64; 3]) {
    let pts = &t.centerline_mm;
    let n = pts.len();
    let tan = |i: usize| {
        let a = pts[i.saturating_sub(1)];
        let b = pts[(i + 1).min(n - 1)];
        norm(sub(b, a))
    };
    let t0 = tan(0);
    let helper = if t0[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let mut r = norm(sub(helper, scale(t0, dot(helper, t0))));
    let target = t.centerline_arc_mm.partition_point(|&a| a < arc).min(n - 1);
    let target = if t.centerline_arc_mm[target] > arc && target > 0 {
        target - 1
    } else {
        target
    };
    for i in 0..target {
        let v1 = sub(pts[i + 1], pts[i]);
        let c1 = dot(v1, v1);
        let r_l = sub(r, scale(v1, 2.0 / c1 * dot(v1, r)));
        let t_l = sub(tan(i), scale(v1, 2.0 / c1 * dot(v1, tan(i))));
        let v2 = sub(tan(i + 1), t_l);
        let c2 = dot(v2, v2);
        let next = if c2 < 1e-18 {
            r_l
        } else {
            sub(r_l, scale(v2, 2.0 / c2 * dot(v2, r_l)))
        };
        let tt = tan(i + 1);
        r = norm(sub(next, scale(tt, dot(next, tt))));
    }
    let tt = tan(target);
    let b = cross(tt, r);
    let dir = norm([0, 1, 2].map(|a| r[a] * angle.cos() + b[a] * angle.sin()));
    let frac = (arc - t.centerline_arc_mm[target])
        / (t.centerline_arc_mm[(target + 1).min(n - 1)] - t.centerline_arc_mm[target]).max(1e-9);
    let q = [0, 1, 2].map(|a| {
        pts[target][a] + (pts[(target + 1).min(n - 1)][a] - pts[target][a]) * frac.clamp(0.0, 1.0)
    });
    (q, dir)
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn norm(a: [f64; 3]) -> [f64; 3] {
    let l = dot(a, a).sqrt().max(1e-300);
    scale(a, 1.0 / l)
}

/// 6–10 polyps of 3–12 mm (scaled), ≥ 1 behind a fold, each a tissue sphere on the wall,
/// protruding into the lumen, in the segment the truth names.
fn check_polyps(p: &Phantom) {
    let t = &p.truth;
    let small = t.scale < 1.0;
    let (lo, hi) = if small { (3.0, 9.0) } else { (3.0, 12.0) };
    assert!(
        (6..=10).contains(&t.polyps.len()),
        "{} polyps",
        t.polyps.len()
    );
    assert!(t.polyps.iter().any(|q| q.behind_fold));
    let segs: std::collections::BTreeSet<&str> =
        t.polyps.iter().map(|q| q.segment.as_str()).collect();
    assert!(segs.len() >= 5, "polyps in only {segs:?}");
    for q in &t.polyps {
        assert!(
            (lo..=hi).contains(&q.diameter_mm),
            "polyp of {} mm",
            q.diameter_mm
        );
        assert_eq!(t.segment_at(q.arc_mm), Some(q.segment.as_str()));
        let c = at(&p.ct, q.center_mm);
        assert!((-60..=150).contains(&c), "polyp centre HU {c}");
        assert_eq!(at(&p.lumen, q.center_mm), 0);
        assert_eq!(at(&p.labels, q.center_mm), label::POLYP);
        assert!(q.protrusion_mm >= 0.7 * q.diameter_mm);
        // The tip (the point nearest the axis) is inside the lumen's nominal radius, and
        // just beyond it (towards the axis) there is lumen.
        let tip = [0, 1, 2]
            .map(|a| q.base_mm[a] + q.direction[a] * (q.protrusion_mm + 1.5 * t.spacing_mm[0]));
        assert_eq!(
            at(&p.lumen, tip),
            1,
            "no lumen in front of the polyp at arc {}",
            q.arc_mm
        );
        let inside = [0, 1, 2].map(|a| {
            q.center_mm[a] + q.direction[a] * (0.5 * q.diameter_mm - 0.6 * t.spacing_mm[0])
        });
        assert_eq!(at(&p.labels, inside), label::POLYP);
    }
}

// ---------------------------------------------------------------------------------------
// Pipe.

#[test]
fn pipe_matches_the_paper() {
    let p = pipe();
    let t = &p.truth;
    assert_eq!(p.ct.dims(), [512, 512, 107]);
    assert_eq!(t.kind, "pipe");
    let d: Vec<f64> = t.polyps.iter().map(|q| q.diameter_mm).collect();
    assert_eq!(d, [7.0, 5.0, 3.0]);
    assert!(t.centerline_radius_mm.iter().all(|&r| r == 20.0));
    assert!(
        t.min_part_gap_mm >= 10.0 + 2.0 * t.wall_thickness_mm,
        "turns {} mm apart",
        t.min_part_gap_mm
    );
    assert!(
        t.centerline_length_mm > 600.0,
        "pipe only {} mm long",
        t.centerline_length_mm
    );
    // Source and target: on the axis, at least half a radius from the caps.
    assert!(t.source_arc_mm >= 10.0 && t.centerline_length_mm - t.target_arc_mm >= 10.0);
    assert_eq!(at(&p.lumen, t.source_mm), 1);
    assert_eq!(at(&p.lumen, t.target_mm), 1);
}

#[test]
fn pipe_centerline_is_inside_the_lumen_20_mm_from_the_wall() {
    let p = pipe();
    let t = &p.truth;
    for pt in &t.centerline_mm {
        assert_eq!(
            at(&p.lumen, *pt),
            1,
            "centerline point {pt:?} not in the lumen"
        );
    }
    // Away from the caps and polyps: lumen at 18.5 mm from the axis, wall at 21.5 mm.
    let near_polyp = |x: [f64; 3]| {
        t.polyps
            .iter()
            .any(|q| dist(x, q.center_mm) < q.diameter_mm + 3.0)
    };
    let mut checked = 0;
    let mut arc = 30.0;
    while arc < t.centerline_length_mm - 30.0 {
        for n in 0..8 {
            let (q, dir) = radial(t, arc, n as f64 * std::f64::consts::TAU / 8.0);
            let inner = [0, 1, 2].map(|a| q[a] + dir[a] * 18.5);
            let outer = [0, 1, 2].map(|a| q[a] + dir[a] * 21.5);
            if near_polyp(inner) {
                continue;
            }
            assert_eq!(
                at(&p.lumen, inner),
                1,
                "no lumen 18.5 mm from the axis at arc {arc}"
            );
            assert_eq!(
                at(&p.lumen, outer),
                0,
                "lumen 21.5 mm from the axis at arc {arc}"
            );
            assert_eq!(
                at(&p.labels, [0, 1, 2].map(|a| q[a] + dir[a] * 21.25)),
                label::WALL
            );
            checked += 1;
        }
        arc += 10.0;
    }
    assert!(checked > 400);
}

#[test]
fn pipe_polyps_are_rubber_on_the_wall() {
    let p = pipe();
    for q in &p.truth.polyps {
        let c = at(&p.ct, q.center_mm);
        assert!((0..=160).contains(&c), "polyp centre HU {c}");
        assert_eq!(at(&p.lumen, q.center_mm), 0);
        assert_eq!(at(&p.labels, q.center_mm), label::POLYP);
        assert!(q.protrusion_mm >= 0.7 * q.diameter_mm);
        // The centre is inside the pipe's radius: the sphere stands in the lumen.
        let (axis, _) = radial(&p.truth, q.arc_mm, 0.0);
        let r = dist(axis, q.center_mm);
        assert!(
            r < 20.0 && r > 20.0 - 0.5 * q.diameter_mm - 1e-6,
            "polyp centre {r} mm from the axis"
        );
    }
}

#[test]
fn pipe_lumen_is_one_capped_component() {
    let p = pipe();
    let comps = components(&p.lumen, |i| p.lumen.data()[i] == 1);
    assert_eq!(comps.len(), 1, "pipe lumen in {} pieces", comps.len());
    assert!(!comps[0].1, "pipe lumen touches the border");
    assert_eq!(comps[0].0, p.truth.lumen_voxels);
    // The pipe's air is sealed: air reached from the border never enters the lumen.
    let outside = flood_from_border(p.ct.dims(), |i| p.ct.data()[i] < -500);
    assert!(
        outside
            .iter()
            .zip(p.lumen.data())
            .all(|(&o, &l)| !(o && l == 1))
    );
    assert!(outside.iter().filter(|&&o| o).count() > 1_000_000);
}

#[test]
fn pipe_hu_values() {
    let p = pipe();
    let t = &p.truth;
    // Deep inside the lumen (≤ 15 mm from the axis, away from the polyps).
    let mut air = Vec::new();
    for (pt, &a) in t.centerline_mm.iter().zip(&t.centerline_arc_mm).step_by(5) {
        if a < 20.0 || a > t.centerline_length_mm - 20.0 {
            continue;
        }
        if t.polyps.iter().any(|q| dist(*pt, q.center_mm) < 25.0) {
            continue;
        }
        air.push(at(&p.ct, *pt) as f64);
    }
    let mean_air = air.iter().sum::<f64>() / air.len() as f64;
    assert!((mean_air + 1000.0).abs() < 30.0, "air {mean_air}");
    let (water, sd) = roi_stats(p);
    assert!(water.abs() < 30.0, "water {water}");
    assert!((sd - 20.0).abs() < 3.0, "noise {sd}");
    let roi = t.noise_roi.as_ref().map(|r| r.expected_hu);
    assert_eq!(roi, Some(0.0));
}

// ---------------------------------------------------------------------------------------
// Colon (small).

#[test]
fn small_colon_truth_and_voxels_agree() {
    let p = small_default();
    assert_eq!(p.ct.dims(), [128, 128, 125]);
    check_colon(p, false);
    // One lumen, off the border.
    let comps = components(&p.lumen, |i| p.lumen.data()[i] == 1);
    assert_eq!(comps.len(), 1, "lumen in {} pieces", comps.len());
    assert!(!comps[0].1, "lumen touches the border");
}

#[test]
fn small_colon_is_deterministic_whatever_the_threads() {
    let opts = ColonOptions {
        small: true,
        tagged_fluid: true,
        seed: 5,
        ..ColonOptions::default()
    };
    let a = phantom::colon(&opts).expect("colon");
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    let b = pool.install(|| phantom::colon(&opts)).expect("colon");
    assert!(
        a.ct.data() == b.ct.data(),
        "CT differs between 1 thread and the default pool"
    );
    assert!(a.lumen.data() == b.lumen.data());
    assert!(a.labels.data() == b.labels.data());
    assert_eq!(a.truth, b.truth);
    let c = phantom::colon(&ColonOptions { seed: 6, ..opts }).expect("colon");
    assert!(a.ct.data() != c.ct.data(), "another seed gives the same CT");
    let differ =
        a.ct.data()
            .iter()
            .zip(c.ct.data())
            .filter(|(x, y)| x != y)
            .count();
    assert!(differ > a.ct.data().len() / 2);
}

#[test]
fn small_colon_loops_never_touch() {
    // Any two lumen voxels closer than the minimum gap (6 mm full size) belong to the same
    // part of the colon: the centerline points whose tube holds them most deeply (smallest
    // distance − radius) are close along the centerline.
    let p = small_default();
    let t = &p.truth;
    let gap = 6.0 * t.scale;
    let lumen: Vec<usize> = (0..p.lumen.data().len())
        .filter(|&i| p.lumen.data()[i] == 1)
        .collect();
    let mut arc_of = std::collections::HashMap::with_capacity(lumen.len());
    for &idx in &lumen {
        let x = local(&p.lumen, idx);
        let (n, _) = t
            .centerline_mm
            .iter()
            .zip(&t.centerline_radius_mm)
            .enumerate()
            .map(|(n, (c, r))| (n, dist(*c, x) - r))
            .fold((0, f64::INFINITY), |b, c| if c.1 < b.1 { c } else { b });
        arc_of.insert(idx, n);
    }
    let [nx, ny, _] = p.lumen.dims();
    let rmax = t.centerline_radius_mm.iter().cloned().fold(0.0, f64::max);
    let same_part = std::f64::consts::PI * (rmax + t.wall_thickness_mm);
    let mut pairs = 0usize;
    for &idx in &lumen {
        let x = local(&p.lumen, idx);
        let [i, j, k] = p.lumen.geometry().ijk(idx);
        for dk in -2i64..=2 {
            for dj in -2i64..=2 {
                for di in -2i64..=2 {
                    let (a, b, c) = (i as i64 + di, j as i64 + dj, k as i64 + dk);
                    if a < 0 || b < 0 || c < 0 {
                        continue;
                    }
                    let m = a as usize + nx * (b as usize + ny * c as usize);
                    let Some(&other) = arc_of.get(&m) else {
                        continue;
                    };
                    if dist(local(&p.lumen, m), x) >= gap {
                        continue;
                    }
                    pairs += 1;
                    let da = (t.centerline_arc_mm[other] - t.centerline_arc_mm[arc_of[&idx]]).abs();
                    assert!(
                        da <= same_part,
                        "lumen at arcs {:.0} and {:.0} mm touch",
                        t.centerline_arc_mm[other],
                        t.centerline_arc_mm[arc_of[&idx]]
                    );
                }
            }
        }
    }
    assert!(pairs > lumen.len());
}

#[test]
fn small_colon_outside_air_reaches_the_border_and_not_the_lumen() {
    let p = small_default();
    let outside = flood_from_border(p.ct.dims(), |i| p.ct.data()[i] < -500);
    let mut reached = 0usize;
    let mut outside_label = 0usize;
    for ((&o, &l), &lab) in outside.iter().zip(p.lumen.data()).zip(p.labels.data()) {
        assert!(!(o && l == 1), "outside air leaks into the lumen");
        // (The lung bases may: like a real scan's, they are cut by the top slice.)
        assert!(
            !(o && lab == label::SMALL_BOWEL_GAS),
            "outside air reaches small-bowel gas"
        );
        reached += o as usize;
        outside_label += (lab == label::OUTSIDE_AIR) as usize;
    }
    assert!(
        reached as f64 > 0.98 * outside_label as f64,
        "{reached} of {outside_label} outside voxels reached"
    );
}

#[test]
fn small_colon_noise_has_the_stated_sigma() {
    for noise in [20.0, 40.0] {
        let p = small(ColonOptions {
            noise_hu: noise,
            lung_bases: false,
            ..ColonOptions::default()
        });
        let (mean, sd) = roi_stats(&p);
        assert!((mean + 100.0).abs() < 0.1 * noise, "fat {mean}");
        assert!((sd - noise).abs() <= 0.15 * noise, "noise {sd} for {noise}");
    }
    let p = small(ColonOptions {
        noise_hu: 0.0,
        ..ColonOptions::default()
    });
    let (mean, sd) = roi_stats(&p);
    assert_eq!((mean, sd), (-100.0, 0.0));
}

#[test]
fn small_colon_distractors_are_not_lumen() {
    let p = small_default();
    let t = &p.truth;
    let gas: Vec<_> = t
        .distractors
        .iter()
        .filter(|d| d.kind == "small_bowel_gas")
        .collect();
    let lungs: Vec<_> = t.distractors.iter().filter(|d| d.kind == "lung").collect();
    assert!(gas.len() >= 2, "{} small-bowel gas pockets", gas.len());
    assert_eq!(lungs.len(), 2);
    for g in &gas {
        let d = 2.0 * g.semi_axes_mm[0] / t.scale;
        assert!((10.0..=20.0).contains(&d), "pocket of {d} mm (full size)");
        assert_eq!(at(&p.lumen, g.center_mm), 0);
        assert_eq!(at(&p.labels, g.center_mm), label::SMALL_BOWEL_GAS);
        assert!(at(&p.ct, g.center_mm) < -850);
        // ≥ 10 mm (scaled) from the colon's lumen.
        for (c, r) in t.centerline_mm.iter().zip(&t.centerline_radius_mm) {
            assert!(dist(*c, g.center_mm) - r - g.semi_axes_mm[0] >= 10.0 * t.scale);
        }
    }
    let [nx, ny, nz] = p.labels.dims();
    let (mut lung_voxels, mut deep_lung) = (0usize, 0usize);
    let mut lung_hu = 0.0;
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                if p.labels.get(i, j, k) == label::LUNG {
                    lung_voxels += 1;
                    let deep =
                        i > 0 && j > 0 && k > 0 && i + 1 < nx && j + 1 < ny && k + 1 < nz && {
                            let n6 = [
                                (i - 1, j, k),
                                (i + 1, j, k),
                                (i, j - 1, k),
                                (i, j + 1, k),
                                (i, j, k - 1),
                                (i, j, k + 1),
                            ];
                            n6.iter()
                                .all(|&(a, b, c)| p.labels.get(a, b, c) == label::LUNG)
                        };
                    if deep {
                        deep_lung += 1;
                        lung_hu += p.ct.get(i, j, k) as f64;
                    }
                    assert_eq!(p.lumen.get(i, j, k), 0);
                    assert!(k + 15 >= nz, "lung at slice {k}");
                }
            }
        }
    }
    assert!(lung_voxels > 1000);
    assert!(
        deep_lung > 100 && (lung_hu / deep_lung as f64 + 850.0).abs() < 10.0,
        "lung HU {}",
        lung_hu / deep_lung.max(1) as f64
    );
    // Without the options, no distractors.
    let q = small(ColonOptions {
        small_bowel_gas: false,
        lung_bases: false,
        ..ColonOptions::default()
    });
    assert!(q.truth.distractors.is_empty());
    assert!(
        q.labels
            .data()
            .iter()
            .all(|&l| l != label::LUNG && l != label::SMALL_BOWEL_GAS)
    );
}

#[test]
fn small_colon_tagged_fluid_lies_flat_in_the_lumen() {
    let p = small(ColonOptions {
        tagged_fluid: true,
        ..ColonOptions::default()
    });
    let t = &p.truth;
    check_colon(&p, false);
    assert!(t.fluid_pools.len() >= 2, "{} pools", t.fluid_pools.len());
    assert!(t.fluid_voxels > 500, "{} fluid voxels", t.fluid_voxels);
    let [nx, ny, nz] = p.ct.dims();
    let sy = p.ct.spacing()[1];
    let (mut deep, mut deep_hu) = (0usize, 0.0);
    let mut levels_seen = 0usize;
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let lab = p.labels.get(i, j, k);
                if lab == label::LUMEN_FLUID {
                    assert_eq!(p.lumen.get(i, j, k), 1);
                    let below = j + 1 < ny && p.labels.get(i, j + 1, k) == label::LUMEN_FLUID;
                    let above = j > 0 && p.labels.get(i, j - 1, k) == label::LUMEN_FLUID;
                    if below && above {
                        deep += 1;
                        deep_hu += p.ct.get(i, j, k) as f64;
                    }
                }
                if j + 1 < ny {
                    let next = p.labels.get(i, j + 1, k);
                    // Fluid never floats above gas (y grows posteriorly, "down").
                    assert!(
                        !(lab == label::LUMEN_FLUID && next == label::LUMEN_AIR),
                        "fluid above gas at {i} {j} {k}"
                    );
                    if lab == label::LUMEN_AIR && next == label::LUMEN_FLUID {
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
    assert!(levels_seen > 50);
    assert!(
        deep > 100 && deep_hu / deep as f64 > 350.0,
        "fluid HU {}",
        deep_hu / deep.max(1) as f64
    );
    for pl in &t.fluid_pools {
        assert!((400.0..=700.0).contains(&pl.hu));
    }
}

#[test]
fn small_colon_collapsed_segment_splits_the_gas() {
    let p = small(ColonOptions {
        collapsed: vec!["descending".into()],
        ..ColonOptions::default()
    });
    let t = &p.truth;
    check_colon(&p, true);
    let c = t.collapsed.first().expect("collapsed stretch in the truth");
    let len = (c.end_arc_mm - c.start_arc_mm) / t.scale;
    assert!(
        (20.0..=40.0).contains(&len),
        "collapsed over {len} mm (full size)"
    );
    let mid = arc_point(t, 0.5 * (c.start_arc_mm + c.end_arc_mm));
    assert_eq!(at(&p.lumen, mid), 0);
    let comps = components(&p.lumen, |i| p.lumen.data()[i] == 1);
    assert_eq!(comps.len(), 2, "lumen in {} pieces", comps.len());
    assert!(comps.iter().all(|c| !c.1 && c.0 > 1000));
    // Source and target are in different pieces.
    let idx = |x: [f64; 3]| {
        let [i, j, k] = voxel_of(&p.lumen, x).expect("inside");
        p.lumen.geometry().index(i, j, k)
    };
    let from_source = flood_from(&p.lumen, idx(t.source_mm));
    assert!(
        !from_source[idx(t.target_mm)],
        "target reachable from source through the collapse"
    );
}

#[test]
fn small_colon_fluid_and_collapse_together() {
    let p = small(ColonOptions {
        tagged_fluid: true,
        collapsed: vec!["descending".into()],
        seed: 3,
        ..ColonOptions::default()
    });
    check_colon(&p, true);
    let t = &p.truth;
    let c = t.collapsed.first().expect("collapse");
    assert!(!t.fluid_pools.is_empty());
    for pl in &t.fluid_pools {
        assert!(
            pl.end_arc_mm <= c.start_arc_mm - c.taper_mm
                || pl.start_arc_mm >= c.end_arc_mm + c.taper_mm
        );
    }
    for (&l, &m) in p.labels.data().iter().zip(p.lumen.data()) {
        assert!(l != label::LUMEN_FLUID || m == 1);
    }
    assert_eq!(components(&p.lumen, |i| p.lumen.data()[i] == 1).len(), 2);
}

#[test]
fn truth_json_round_trips() {
    for p in [small_default(), pipe()] {
        let json = p.truth.to_json();
        assert!(json.contains("volume-local"));
        let back = Truth::from_json(&json).expect("parse");
        // Numbers may come back within an ulp (serde_json parses floats fast, not exactly).
        let v: serde_json::Value = serde_json::from_str(&json).expect("json");
        let w = serde_json::to_value(&back).expect("value");
        assert!(json_close(&v, &w), "truth changed on the way through JSON");
        assert_eq!(back.polyps.len(), p.truth.polyps.len());
        assert_eq!(back.segments, p.truth.segments);
        assert!(
            v["centerline_mm"]
                .as_array()
                .is_some_and(|a| a.len() == p.truth.centerline_mm.len())
        );
    }
}

/// Equal JSON values, numbers to 1e-12 relative.
fn json_close(a: &serde_json::Value, b: &serde_json::Value) -> bool {
    use serde_json::Value as V;
    match (a, b) {
        (V::Number(x), V::Number(y)) => {
            let (x, y) = (
                x.as_f64().unwrap_or(f64::NAN),
                y.as_f64().unwrap_or(f64::NAN),
            );
            (x - y).abs() <= 1e-12 * x.abs().max(y.abs()).max(1.0)
        }
        (V::Array(x), V::Array(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(p, q)| json_close(p, q))
        }
        (V::Object(x), V::Object(y)) => {
            x.len() == y.len()
                && x.iter()
                    .all(|(k, p)| y.get(k).is_some_and(|q| json_close(p, q)))
        }
        _ => a == b,
    }
}

// ---------------------------------------------------------------------------------------
// Colon (full size): one test, timing-free invariants.

#[test]
fn full_colon_invariants() {
    let p = phantom::colon(&ColonOptions::default()).expect("colon");
    let t = &p.truth;
    assert_eq!(p.ct.dims(), [512, 512, 400]);
    assert_eq!(t.spacing_mm, [0.75, 0.75, 1.0]);
    assert_eq!(t.scale, 1.0);
    check_colon(&p, false);
    let comps = components(&p.lumen, |i| p.lumen.data()[i] == 1);
    assert_eq!(comps.len(), 1, "lumen in {} pieces", comps.len());
    assert!(!comps[0].1);
    let (mean, sd) = roi_stats(&p);
    assert!(
        (mean + 100.0).abs() < 2.0 && (sd - 20.0).abs() <= 3.0,
        "fat {mean} ± {sd}"
    );
    // Lungs only in the top 30 slices, never lumen; outside air reaches the border.
    let [nx, ny, nz] = p.ct.dims();
    let plane = nx * ny;
    for (idx, &l) in p.labels.data().iter().enumerate() {
        if l == label::LUNG {
            assert!(idx / plane + 30 >= nz);
        }
    }
    let outside = flood_from_border(p.ct.dims(), |i| p.ct.data()[i] < -500);
    assert!(
        outside
            .iter()
            .zip(p.lumen.data())
            .all(|(&o, &l)| !(o && l == 1))
    );
    let out_label = p
        .labels
        .data()
        .iter()
        .filter(|&&l| l == label::OUTSIDE_AIR)
        .count();
    let reached = outside.iter().filter(|&&o| o).count();
    assert!(reached as f64 > 0.98 * out_label as f64);
    // Behind-fold polyps are hidden from 30 mm up the colon: the straight line from the
    // axis there to the polyp's centre crosses fold tissue before it reaches the polyp.
    for q in t.polyps.iter().filter(|q| q.behind_fold) {
        let eye = arc_point(t, q.arc_mm - 30.0);
        let steps = 400;
        let mut crossed_wall = false;
        for n in 0..=steps {
            let f = n as f64 / steps as f64;
            let x = [0, 1, 2].map(|a| eye[a] + (q.center_mm[a] - eye[a]) * f);
            let l = at(&p.labels, x);
            if l == label::POLYP {
                break;
            }
            crossed_wall |= l == label::WALL;
        }
        assert!(
            crossed_wall,
            "the {} mm polyp at arc {:.0} is in plain view",
            q.diameter_mm, q.arc_mm
        );
    }
}

#[test]
fn segmentation_extent_is_the_lumen_bounding_box_with_and_without_fluid() {
    // Later stages take the lumen's box from the segmentation instead of reading the mask.
    for fluid in [false, true] {
        let p = small(ColonOptions {
            tagged_fluid: fluid,
            ..ColonOptions::default()
        });
        let seg = voyage_core::segment(&p.ct, &Default::default()).expect("segment");
        assert_eq!(
            seg.fluid_voxels > 0,
            fluid,
            "fluid taken: {}",
            seg.fluid_voxels
        );
        let b = voyage_core::bounding_box(&seg.lumen, 0, |v| v != 0).expect("lumen");
        let last = [0, 1, 2].map(|a| b.lo[a] + b.dims[a] - 1);
        assert_eq!(seg.extent, [b.lo, last], "fluid {fluid}");
    }
}
