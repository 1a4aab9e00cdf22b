//! The volume model: a dense 3D grid of voxels with its place in the patient.
//!
//! Storage is x fastest: `index = i + nx * (j + ny * k)`. Geometry follows DICOM: `origin`
//! is the patient position (LPS, mm) of voxel (0,0,0); the columns of `direction` are the
//! unit vectors, in LPS, of the i, j and k axes. Inside the pipeline everything is in
//! *volume-local millimetres* (x = i·sx, y = j·sy, z = k·sz); patient coordinates appear
//! only at the edges (loading, exports, read-outs).

use glam::{DMat3, DVec3};

use crate::{Error, Result};

/// Refuse volumes larger than this many voxels: 2^31 voxels of i16 is 4 GiB, far beyond any
/// CT colonography scan, and a header asking for more is corrupt or hostile.
pub const MAX_VOXELS: u64 = 1 << 31;
/// Refuse any single dimension larger than this.
pub const MAX_DIM: u64 = 1 << 16;

#[derive(Clone, Debug, PartialEq)]
pub struct Geometry {
    pub dims: [usize; 3],
    /// Voxel size in mm along i, j, k. Always finite and > 0.
    pub spacing: [f64; 3],
    /// Patient position (LPS, mm) of the centre of voxel (0,0,0).
    pub origin: [f64; 3],
    /// Columns are the LPS unit vectors of the i, j, k axes (row-major storage: `direction[r][c]`).
    pub direction: [[f64; 3]; 3],
}

impl Geometry {
    /// Axis-aligned geometry with the identity direction (i→L, j→P, k→S).
    pub fn new(dims: [usize; 3], spacing: [f64; 3], origin: [f64; 3]) -> Result<Self> {
        let g = Geometry {
            dims,
            spacing,
            origin,
            direction: IDENTITY,
        };
        g.validate()?;
        Ok(g)
    }

    /// Checks dimensions (non-zero, not absurd) and spacing (finite, positive).
    pub fn validate(&self) -> Result<()> {
        check_dims(self.dims.map(|d| d as u64))?;
        if self.spacing.iter().any(|s| !s.is_finite() || *s <= 0.0) {
            return Err(Error::invalid(format!(
                "voxel spacing {:?} mm is not positive and finite",
                self.spacing
            )));
        }
        if self.origin.iter().any(|o| !o.is_finite()) {
            return Err(Error::invalid(format!(
                "origin {:?} is not finite",
                self.origin
            )));
        }
        let d = self.direction_mat();
        if !d.is_finite() || (d.determinant().abs() - 1.0).abs() > 1e-3 {
            return Err(Error::invalid(format!(
                "direction matrix {:?} is not a rotation",
                self.direction
            )));
        }
        Ok(())
    }

    pub fn len(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    #[inline]
    pub fn index(&self, i: usize, j: usize, k: usize) -> usize {
        grid_index(self.dims, i, j, k)
    }

    /// Inverse of [`Geometry::index`].
    #[inline]
    pub fn ijk(&self, index: usize) -> [usize; 3] {
        grid_ijk(self.dims, index)
    }

    pub fn direction_mat(&self) -> DMat3 {
        let d = &self.direction;
        DMat3::from_cols(
            DVec3::new(d[0][0], d[1][0], d[2][0]),
            DVec3::new(d[0][1], d[1][1], d[2][1]),
            DVec3::new(d[0][2], d[1][2], d[2][2]),
        )
    }

    pub fn set_direction_mat(&mut self, m: DMat3) {
        for c in 0..3 {
            let col = m.col(c);
            self.direction[0][c] = col.x;
            self.direction[1][c] = col.y;
            self.direction[2][c] = col.z;
        }
    }

    pub fn spacing_vec(&self) -> DVec3 {
        DVec3::from_array(self.spacing)
    }

    /// Continuous voxel index → volume-local millimetres.
    #[inline]
    /// The centre of voxel `index` (flat, x fastest) in volume-local mm.
    pub fn voxel_local(&self, index: usize) -> DVec3 {
        self.index_to_local(DVec3::from_array(self.ijk(index).map(|x| x as f64)))
    }

    pub fn index_to_local(&self, ijk: DVec3) -> DVec3 {
        ijk * self.spacing_vec()
    }

    /// Volume-local millimetres → continuous voxel index.
    #[inline]
    pub fn local_to_index(&self, mm: DVec3) -> DVec3 {
        mm / self.spacing_vec()
    }

    /// A volume-local point as messages give it: in patient LPS mm, the frame viewers and the
    /// command line use, and as the nearest voxel (which may lie outside the volume).
    pub fn describe_point(&self, mm: DVec3) -> String {
        let p = self.local_to_patient(mm);
        let v = self.local_to_index(mm).round();
        format!(
            "at LPS ({:.1}, {:.1}, {:.1}) mm, voxel ({}, {}, {})",
            p.x, p.y, p.z, v.x as i64, v.y as i64, v.z as i64
        )
    }

    /// Volume-local millimetres → patient LPS millimetres.
    pub fn local_to_patient(&self, mm: DVec3) -> DVec3 {
        DVec3::from_array(self.origin) + self.direction_mat() * mm
    }

    /// Patient LPS millimetres → volume-local millimetres.
    pub fn patient_to_local(&self, lps: DVec3) -> DVec3 {
        self.direction_mat().transpose() * (lps - DVec3::from_array(self.origin))
    }

    pub fn index_to_patient(&self, ijk: DVec3) -> DVec3 {
        self.local_to_patient(self.index_to_local(ijk))
    }

    pub fn patient_to_index(&self, lps: DVec3) -> DVec3 {
        self.local_to_index(self.patient_to_local(lps))
    }

    /// The patient-LPS box (min, max corners) of the voxel box `lo..=hi`: all eight corners,
    /// as the direction may turn the axes.
    pub fn patient_box(&self, lo: [usize; 3], hi: [usize; 3]) -> [DVec3; 2] {
        let (mut a, mut b) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for c in 0..8 {
            let v = [0, 1, 2].map(|x| if c >> x & 1 == 1 { hi[x] } else { lo[x] } as f64);
            let p = self.index_to_patient(DVec3::from_array(v));
            (a, b) = (a.min(p), b.max(p));
        }
        [a, b]
    }

    /// Size of the volume in mm (from first to last voxel centre, plus one voxel).
    pub fn extent_mm(&self) -> DVec3 {
        DVec3::new(
            self.dims[0] as f64,
            self.dims[1] as f64,
            self.dims[2] as f64,
        ) * self.spacing_vec()
    }

    /// Whether the continuous index lies inside the grid of voxel centres.
    pub fn contains_index(&self, ijk: DVec3) -> bool {
        (0..3).all(|a| ijk[a] >= 0.0 && ijk[a] <= (self.dims[a] - 1) as f64)
    }

    /// A short orientation code such as "LPS" or "RAS": for each voxel axis, the patient
    /// direction it points to most.
    pub fn orientation_code(&self) -> String {
        let m = self.direction_mat();
        (0..3)
            .map(|c| {
                let v = m.col(c);
                let a = v.abs();
                let (axis, sign) = if a.x >= a.y && a.x >= a.z {
                    (0, v.x)
                } else if a.y >= a.z {
                    (1, v.y)
                } else {
                    (2, v.z)
                };
                let (pos, neg) = [('L', 'R'), ('P', 'A'), ('S', 'I')][axis];
                if sign >= 0.0 { pos } else { neg }
            })
            .collect()
    }
}

/// Linear index of voxel (i, j, k) in an x-fastest grid of `dims`.
#[inline]
pub fn grid_index(dims: [usize; 3], i: usize, j: usize, k: usize) -> usize {
    i + dims[0] * (j + dims[1] * k)
}

/// Inverse of [`grid_index`].
#[inline]
pub fn grid_ijk(dims: [usize; 3], index: usize) -> [usize; 3] {
    [
        index % dims[0],
        (index / dims[0]) % dims[1],
        index / (dims[0] * dims[1]),
    ]
}

/// The six face neighbours of voxel `index` (−x, +x, −y, +y, −z, +z), None past the edge.
#[inline]
pub fn face_neighbours(dims: [usize; 3], index: usize) -> [Option<usize>; 6] {
    let [x, y, z] = grid_ijk(dims, index);
    let (sy, sz) = (dims[0], dims[0] * dims[1]);
    [
        (x > 0).then(|| index - 1),
        (x + 1 < dims[0]).then(|| index + 1),
        (y > 0).then(|| index - sy),
        (y + 1 < dims[1]).then(|| index + sy),
        (z > 0).then(|| index - sz),
        (z + 1 < dims[2]).then(|| index + sz),
    ]
}

pub const IDENTITY: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// Validates header dimensions before anything is allocated.
pub fn check_dims(dims: [u64; 3]) -> Result<()> {
    if dims.contains(&0) {
        return Err(Error::invalid(format!("dimensions {dims:?} contain zero")));
    }
    if dims.iter().any(|&d| d > MAX_DIM) {
        return Err(Error::invalid(format!(
            "dimensions {dims:?} exceed the limit of {MAX_DIM} per axis"
        )));
    }
    let n = dims[0].saturating_mul(dims[1]).saturating_mul(dims[2]);
    if n > MAX_VOXELS {
        return Err(Error::invalid(format!(
            "dimensions {dims:?} give {n} voxels, over the limit of {MAX_VOXELS}"
        )));
    }
    Ok(())
}

/// A dense voxel grid with geometry.
#[derive(Clone, Debug, PartialEq)]
pub struct Volume<T> {
    geom: Geometry,
    data: Vec<T>,
}

impl<T: Copy> Volume<T> {
    pub fn from_vec(geom: Geometry, data: Vec<T>) -> Result<Self> {
        geom.validate()?;
        if data.len() != geom.len() {
            return Err(Error::invalid(format!(
                "volume of dims {:?} needs {} voxels, got {}",
                geom.dims,
                geom.len(),
                data.len()
            )));
        }
        Ok(Volume { geom, data })
    }

    pub fn filled(geom: Geometry, value: T) -> Result<Self> {
        geom.validate()?;
        let n = geom.len();
        Ok(Volume {
            geom,
            data: vec![value; n],
        })
    }

    pub fn geometry(&self) -> &Geometry {
        &self.geom
    }
    pub fn geometry_mut(&mut self) -> &mut Geometry {
        &mut self.geom
    }
    pub fn dims(&self) -> [usize; 3] {
        self.geom.dims
    }
    pub fn spacing(&self) -> [f64; 3] {
        self.geom.spacing
    }
    pub fn data(&self) -> &[T] {
        &self.data
    }
    pub fn data_mut(&mut self) -> &mut [T] {
        &mut self.data
    }
    pub fn into_data(self) -> Vec<T> {
        self.data
    }
    #[inline]
    pub fn get(&self, i: usize, j: usize, k: usize) -> T {
        self.data[self.geom.index(i, j, k)]
    }
    #[inline]
    pub fn set(&mut self, i: usize, j: usize, k: usize, v: T) {
        let idx = self.geom.index(i, j, k);
        self.data[idx] = v;
    }
    /// Same geometry, values mapped voxel by voxel.
    pub fn map<U: Copy>(&self, f: impl Fn(T) -> U) -> Volume<U> {
        Volume {
            geom: self.geom.clone(),
            data: self.data.iter().map(|&v| f(v)).collect(),
        }
    }
    /// One axial slice (fixed k), x fastest.
    pub fn slice_k(&self, k: usize) -> &[T] {
        let n = self.geom.dims[0] * self.geom.dims[1];
        &self.data[k * n..(k + 1) * n]
    }
}

impl<T: Copy + Send + Sync> Volume<T> {
    /// The same voxels stored another way: new axis `a` is old axis `perm[a]`, reversed where
    /// `flip[a]`. The geometry changes with it, so every voxel keeps its patient position: the
    /// same scan as another scanner or converter would have stored it.
    pub fn reoriented(&self, perm: [usize; 3], flip: [bool; 3]) -> Result<Volume<T>> {
        let mut sorted = perm;
        sorted.sort_unstable();
        if sorted != [0, 1, 2] {
            return Err(Error::invalid(format!(
                "axis order {perm:?} is not a permutation of 0, 1, 2"
            )));
        }
        use rayon::prelude::*;
        let old = &self.geom;
        let dims = perm.map(|a| old.dims[a]);
        let strides = [1, old.dims[0], old.dims[0] * old.dims[1]];
        // Old index of new voxel (0, 0, 0) and its step per new axis.
        let mut base = 0isize;
        let mut step = [0isize; 3];
        for a in 0..3 {
            let s = strides[perm[a]] as isize;
            if flip[a] {
                base += s * (dims[a] as isize - 1);
                step[a] = -s;
            } else {
                step[a] = s;
            }
        }
        let mut data = Vec::with_capacity(old.len());
        let row_start = |row: usize| {
            let (j, k) = (row % dims[1], row / dims[1]);
            base + step[1] * j as isize + step[2] * k as isize
        };
        if step[0].abs() == 1 {
            // Rows stay rows (only their order or direction changes): copied whole, at the
            // speed of memory (a scan stored feet first is flipped so before segmentation).
            let n = dims[0];
            for row in 0..dims[1] * dims[2] {
                let start = row_start(row);
                if step[0] > 0 {
                    data.extend_from_slice(&self.data[start as usize..start as usize + n]);
                } else {
                    let first = (start + 1 - n as isize) as usize;
                    data.extend(self.data[first..=start as usize].iter().rev());
                }
            }
        } else {
            data.par_extend((0..dims[1] * dims[2]).into_par_iter().flat_map_iter(|row| {
                let start = row_start(row);
                (0..dims[0]).map(move |i| self.data[(start + step[0] * i as isize) as usize])
            }));
        }
        let mut corner = [0.0; 3];
        for a in 0..3 {
            corner[perm[a]] = if flip[a] { (dims[a] - 1) as f64 } else { 0.0 };
        }
        let m = old.direction_mat();
        let cols = [0, 1, 2].map(|a| m.col(perm[a]) * if flip[a] { -1.0 } else { 1.0 });
        let mut geom = Geometry {
            dims,
            spacing: perm.map(|a| old.spacing[a]),
            origin: old.index_to_patient(DVec3::from_array(corner)).to_array(),
            direction: IDENTITY,
        };
        geom.set_direction_mat(glam::DMat3::from_cols(cols[0], cols[1], cols[2]));
        Volume::from_vec(geom, data)
    }
}

impl<T: Copy + PartialOrd> Volume<T> {
    /// (min, max) of all voxels.
    pub fn min_max(&self) -> (T, T) {
        let mut lo = self.data[0];
        let mut hi = self.data[0];
        for &v in &self.data {
            if v < lo {
                lo = v;
            }
            if v > hi {
                hi = v;
            }
        }
        (lo, hi)
    }
}

/// The first maximal run of consecutive entries of `s` from index `from` on where `inside`
/// holds.
///
/// Runs in a CT row are long (air outside the body, soft tissue, the lumen itself): whole
/// chunks of 16 that lie on one side are stepped over with a test that has no early exit and
/// so compiles to vector compares; only the chunk where the run starts or ends is walked one
/// entry at a time.
#[inline]
pub(crate) fn next_run<T: Copy>(
    s: &[T],
    from: usize,
    inside: impl Fn(T) -> bool,
) -> Option<std::ops::Range<usize>> {
    const W: usize = 16;
    let mut q = from;
    while q + W <= s.len() && !s[q..q + W].iter().fold(false, |a, &v| a | inside(v)) {
        q += W;
    }
    while q < s.len() && !inside(s[q]) {
        q += 1;
    }
    let start = q;
    while q + W <= s.len() && s[q..q + W].iter().fold(true, |a, &v| a & inside(v)) {
        q += W;
    }
    while q < s.len() && inside(s[q]) {
        q += 1;
    }
    (q > start).then_some(start..q)
}

/// The maximal runs of consecutive entries of `s` where `inside` holds, in order.
pub(crate) fn runs_where<T: Copy>(
    s: &[T],
    inside: impl Fn(T) -> bool,
) -> impl Iterator<Item = std::ops::Range<usize>> {
    let mut q = 0;
    std::iter::from_fn(move || {
        let run = next_run(s, q, &inside)?;
        q = run.end;
        Some(run)
    })
}

/// The voxel offsets within `r_mm` of a voxel's centre, for voxels (or cells) of `spacing`.
pub(crate) fn ball_offsets(spacing: [f64; 3], r_mm: f64) -> Vec<[i64; 3]> {
    let r = spacing.map(|s| (r_mm / s).floor() as i64);
    let mut ball = Vec::new();
    for dz in -r[2]..=r[2] {
        for dy in -r[1]..=r[1] {
            for dx in -r[0]..=r[0] {
                let d2 = (dx as f64 * spacing[0]).powi(2)
                    + (dy as f64 * spacing[1]).powi(2)
                    + (dz as f64 * spacing[2]).powi(2);
                if d2 <= r_mm * r_mm {
                    ball.push([dx, dy, dz]);
                }
            }
        }
    }
    ball
}

/// The voxels of `mask` that are not 0 within `r` mm of `p` (volume-local mm).
pub(crate) fn set_voxels_in_ball(mask: &Volume<u8>, p: [f64; 3], r: f64) -> Vec<[usize; 3]> {
    let sp = mask.spacing();
    let dims = mask.dims();
    let lo = [0, 1, 2].map(|a| ((p[a] - r) / sp[a]).floor().max(0.0) as usize);
    let hi = [0, 1, 2].map(|a| (((p[a] + r) / sp[a]).ceil().max(0.0) as usize).min(dims[a] - 1));
    let mut out = Vec::new();
    for k in lo[2]..=hi[2] {
        for j in lo[1]..=hi[1] {
            for i in lo[0]..=hi[0] {
                let d2: f64 = [i, j, k]
                    .iter()
                    .enumerate()
                    .map(|(a, &x)| (x as f64 * sp[a] - p[a]).powi(2))
                    .sum();
                if d2 <= r * r && mask.get(i, j, k) != 0 {
                    out.push([i, j, k]);
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn index_round_trip() {
        let g = Geometry::new([5, 7, 3], [0.8, 0.8, 1.25], [10.0, -20.0, 30.0]).unwrap();
        for idx in [0, 1, 34, 104] {
            let [i, j, k] = g.ijk(idx);
            assert_eq!(g.index(i, j, k), idx);
        }
    }

    #[test]
    fn patient_round_trip_with_rotation() {
        let mut g = Geometry::new([4, 4, 4], [0.5, 0.7, 2.0], [1.0, 2.0, 3.0]).unwrap();
        // A 90° turn about z: i → P, j → R.
        g.direction = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        let p = g.index_to_patient(DVec3::new(1.0, 2.0, 3.0));
        assert!((p - DVec3::new(1.0 - 1.4, 2.0 + 0.5, 3.0 + 6.0)).length() < 1e-12);
        let back = g.patient_to_index(p);
        assert!((back - DVec3::new(1.0, 2.0, 3.0)).length() < 1e-12);
        assert_eq!(g.orientation_code(), "PRS");
    }

    #[test]
    fn reoriented_keeps_every_voxel_at_its_patient_position() {
        let mut g = Geometry::new([3, 4, 5], [0.5, 0.7, 2.0], [1.0, 2.0, 3.0]).unwrap();
        g.direction = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        let v = Volume::from_vec(g.clone(), (0..60).collect::<Vec<i32>>()).unwrap();
        for perm in [[0, 1, 2], [2, 0, 1], [1, 2, 0], [0, 2, 1]] {
            for f in 0..8 {
                let flip = [f & 1 != 0, f & 2 != 0, f & 4 != 0];
                let r = v.reoriented(perm, flip).unwrap();
                assert_eq!(r.dims(), perm.map(|a| g.dims[a]));
                for idx in 0..60 {
                    let [i, j, k] = r.geometry().ijk(idx);
                    let p = r
                        .geometry()
                        .index_to_patient(DVec3::new(i as f64, j as f64, k as f64));
                    let o = g.patient_to_index(p).round();
                    assert!((g.patient_to_index(p) - o).length() < 1e-9);
                    assert_eq!(
                        r.data()[idx],
                        v.get(o.x as usize, o.y as usize, o.z as usize),
                        "{perm:?} {flip:?}"
                    );
                }
            }
        }
        assert!(v.reoriented([0, 0, 1], [false; 3]).is_err());
    }

    #[test]
    fn absurd_dims_refused() {
        assert!(check_dims([100_000, 100_000, 100_000]).is_err());
        assert!(check_dims([512, 512, 0]).is_err());
        assert!(check_dims([512, 512, 400]).is_ok());
        assert!(Geometry::new([2, 2, 2], [0.0, 1.0, 1.0], [0.0; 3]).is_err());
    }

    #[test]
    fn from_vec_checks_length() {
        let g = Geometry::new([2, 2, 2], [1.0; 3], [0.0; 3]).unwrap();
        assert!(Volume::from_vec(g.clone(), vec![0i16; 7]).is_err());
        let v = Volume::from_vec(g, (0..8).collect::<Vec<i16>>()).unwrap();
        assert_eq!(v.get(1, 1, 1), 7);
        assert_eq!(v.min_max(), (0, 7));
    }

    #[test]
    fn runs_are_the_maximal_stretches_where_the_predicate_holds() {
        let s = [0u8, 1, 1, 0, 0, 3, 0, 2, 2];
        assert_eq!(
            runs_where(&s, |x| x != 0).collect::<Vec<_>>(),
            vec![1..3, 5..6, 7..9]
        );
        assert_eq!(next_run(&s, 2, |x| x != 0), Some(2..3));
        assert_eq!(runs_where(&[0u8; 4], |x| x != 0).count(), 0);
    }

    #[test]
    fn runs_agree_with_a_plain_scan() {
        let mut rng = crate::rng::Rng::new(7, 1);
        for len in [0usize, 1, 15, 16, 17, 40, 512] {
            for p in [0.02, 0.5, 0.98] {
                let row: Vec<i16> = (0..len)
                    .map(|_| if rng.range(0.0, 1.0) < p { -1000 } else { 40 })
                    .collect();
                let mut want = Vec::new();
                let mut i = 0;
                while i < len {
                    if row[i] < -500 {
                        let a = i;
                        while i < len && row[i] < -500 {
                            i += 1;
                        }
                        want.push(a..i);
                    } else {
                        i += 1;
                    }
                }
                assert_eq!(
                    runs_where(&row, |v| v < -500).collect::<Vec<_>>(),
                    want,
                    "{row:?}"
                );
            }
        }
    }
}
