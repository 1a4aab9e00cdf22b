//! For tests and benchmarks: random points in a study's lumen; the real data beside the checkout (`../shared/data`) and how a test that cannot
//! run says so. Where `VOYAGE_REQUIRE_ALL` is set (CI sets it) such a test fails instead, so
//! that a skip is never a silent pass.

use std::path::PathBuf;

use glam::DVec3;
use voyage_core::{Study, Volume};

/// `../shared/data` beside the checkout, or None after [`skip`] where it is not there.
pub fn shared_data() -> Option<PathBuf> {
    let path = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data"));
    if path.is_dir() {
        Some(path)
    } else {
        skip(&format!("{} not found", path.display()));
        None
    }
}

/// The file `rel` of the shared data, or None after [`skip`].
pub fn shared_file(rel: &str) -> Option<PathBuf> {
    let path = shared_data()?.join(rel);
    if !path.exists() {
        skip(&format!("{} not found", path.display()));
        return None;
    }
    Some(path)
}

/// The real colon mask `masks/colon-a.nii.gz` of the shared data, or None after [`skip`].
pub fn colon_a_path() -> Option<PathBuf> {
    shared_file("masks/colon-a.nii.gz")
}

/// A test that cannot run here says why on stderr; where `VOYAGE_REQUIRE_ALL` is set it
/// panics instead.
pub fn skip(why: &str) {
    assert!(
        std::env::var_os("VOYAGE_REQUIRE_ALL").is_none(),
        "cannot run: {why} (VOYAGE_REQUIRE_ALL is set)"
    );
    eprintln!("skipping: {why}");
}

/// `n` points drawn uniformly in the lumen's box, kept where the nearest voxel is lumen
/// (many lie within a voxel of the wall): for tests and benchmarks of the fields.
pub fn random_lumen_points(study: &Study, n: usize, seed: u64) -> Vec<DVec3> {
    let mut rng = voyage_core::rng::Rng::new(seed, 1);
    let grid = &study.ds.grid;
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let ijk = DVec3::new(
            grid.lo[0] as f64 + rng.range(0.0, (grid.dims[0] - 1) as f64),
            grid.lo[1] as f64 + rng.range(0.0, (grid.dims[1] - 1) as f64),
            grid.lo[2] as f64 + rng.range(0.0, (grid.dims[2] - 1) as f64),
        );
        let v = ijk.round();
        if study
            .segmentation
            .lumen
            .get(v.x as usize, v.y as usize, v.z as usize)
            != 0
        {
            out.push(study.ct.geometry().index_to_local(ijk));
        }
    }
    out
}

/// Asserts that two volumes have the same geometry (to 1e-5 mm in spacing, 1e-4 mm in origin,
/// 1e-6 in direction) and the same voxels; `what` names them in the failure.
pub fn assert_same_volume(a: &Volume<i16>, b: &Volume<i16>, what: &str) {
    let (ga, gb) = (a.geometry(), b.geometry());
    assert_eq!(ga.dims, gb.dims, "{what}: dims");
    for i in 0..3 {
        assert!(
            (ga.spacing[i] - gb.spacing[i]).abs() < 1e-5,
            "{what}: spacing {:?} vs {:?}",
            ga.spacing,
            gb.spacing
        );
        assert!(
            (ga.origin[i] - gb.origin[i]).abs() < 1e-4,
            "{what}: origin {:?} vs {:?}",
            ga.origin,
            gb.origin
        );
        for j in 0..3 {
            assert!(
                (ga.direction[i][j] - gb.direction[i][j]).abs() < 1e-6,
                "{what}: direction"
            );
        }
    }
    assert!(a.data() == b.data(), "{what}: voxels differ");
}

/// `v` in slabs of `n` slices, as an exam with thicker slices would come: each value the mean
/// of `n` (ties to even, as numpy rounds), or with `max` the largest (for a mask). The first
/// thick slice's centre lies in the middle of the `n` it stands for.
pub fn thick_slices(v: &Volume<i16>, n: usize, max: bool) -> Volume<i16> {
    let g = v.geometry();
    let [nx, ny, nz] = g.dims;
    let slab = nx * ny;
    let thick_nz = nz / n;
    let mut data = vec![0i16; slab * thick_nz];
    for (k, out) in data.chunks_mut(slab).enumerate() {
        let slices: Vec<&[i16]> = (0..n)
            .map(|d| &v.data()[slab * (n * k + d)..slab * (n * k + d + 1)])
            .collect();
        for (x, o) in out.iter_mut().enumerate() {
            let vals = slices.iter().map(|s| s[x] as i32);
            *o = if max {
                vals.max().unwrap() as i16
            } else {
                (vals.sum::<i32>() as f64 / n as f64).round_ties_even() as i16
            };
        }
    }
    let mut thick = g.clone();
    thick.dims = [nx, ny, thick_nz];
    thick.spacing[2] *= n as f64;
    for (o, d) in thick.origin.iter_mut().zip(0..3) {
        *o += g.direction[d][2] * g.spacing[2] * (n - 1) as f64 / 2.0;
    }
    Volume::from_vec(thick, data).unwrap()
}
