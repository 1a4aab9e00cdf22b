//! The storage every scan is prepared in: its axes permuted and flipped to run along the
//! patient's x (left), y (posterior) and z (superior). Nothing downstream then depends on how
//! the scan was stored: coarse blocks, ties between equal distances and one-voxel choices
//! fall the same way for every axis order and flip (on `ctc/prone-tagged` the centerline's
//! length moved by 400 mm between storage orders before), and the study's local frame is
//! right-handed in the patient, so no view is a mirror image.
//!
//! [`Storage`] maps between the scan as given (the *input* storage) and this one (the
//! *study* storage): volumes, voxels and volume-local mm.

use glam::DVec3;

use crate::{Geometry, Result, Volume, anatomy::PatientFrame};

/// How the study storage is made from a scan's input storage: `Volume::reoriented(perm,
/// flip)`, and the input's geometry to go back.
#[derive(Clone, Debug)]
pub struct Storage {
    perm: [usize; 3],
    flip: [bool; 3],
    /// The study storage's dims and spacing.
    dims: [usize; 3],
    spacing: [f64; 3],
    input: Geometry,
}

impl Storage {
    /// The study storage of a scan of geometry `g`. Where the axes do not match the patient's
    /// one to one (very oblique), only the axial axis is put last.
    pub fn of(g: &Geometry) -> Storage {
        let (perm, flip) = canonical(g);
        Storage {
            perm,
            flip,
            dims: perm.map(|a| g.dims[a]),
            spacing: perm.map(|a| g.spacing[a]),
            input: g.clone(),
        }
    }

    /// True when the scan is stored the study's way already.
    pub fn is_identity(&self) -> bool {
        self.perm == [0, 1, 2] && self.flip == [false; 3]
    }

    /// The input's geometry.
    pub fn input_geometry(&self) -> &Geometry {
        &self.input
    }

    /// `v`, stored as the input, in the study storage.
    pub fn to_study<T: Copy + Send + Sync>(&self, v: &Volume<T>) -> Result<Volume<T>> {
        v.reoriented(self.perm, self.flip)
    }

    /// `v`, in the study storage, stored as the input (with the input's geometry exactly).
    pub fn to_input<T: Copy + Send + Sync>(&self, v: &Volume<T>) -> Result<Volume<T>> {
        let mut back = v.reoriented(self.inverse_perm(), self.inverse_flip())?;
        *back.geometry_mut() = self.input.clone();
        Ok(back)
    }

    /// Input volume-local mm to study.
    pub fn mm_in(&self, p: DVec3) -> DVec3 {
        DVec3::from_array([0, 1, 2].map(|a| {
            let x = p[self.perm[a]];
            if self.flip[a] {
                (self.dims[a] - 1) as f64 * self.spacing[a] - x
            } else {
                x
            }
        }))
    }

    /// Study volume-local mm to input.
    pub fn mm_back(&self, p: [f64; 3]) -> [f64; 3] {
        let mut o = [0.0; 3];
        for a in 0..3 {
            o[self.perm[a]] = if self.flip[a] {
                (self.dims[a] - 1) as f64 * self.spacing[a] - p[a]
            } else {
                p[a]
            };
        }
        o
    }

    /// Input voxel to study.
    pub fn voxel_in(&self, v: [usize; 3]) -> [usize; 3] {
        [0, 1, 2].map(|a| {
            let x = v[self.perm[a]];
            if self.flip[a] {
                self.dims[a] - 1 - x
            } else {
                x
            }
        })
    }

    /// The input's axial slice `k` (x fastest) of a study volume read by `value` at study
    /// voxels: for writing a study's field on the input's grid without a second copy of it.
    pub fn fill_input_slice<T>(&self, k: usize, out: &mut [T], value: impl Fn([usize; 3]) -> T) {
        let [nx, ny, _] = self.input.dims;
        for j in 0..ny {
            for i in 0..nx {
                out[i + nx * j] = value(self.voxel_in([i, j, k]));
            }
        }
    }

    /// Study voxel to input.
    pub fn voxel_back(&self, v: [usize; 3]) -> [usize; 3] {
        let mut o = [0; 3];
        for a in 0..3 {
            o[self.perm[a]] = if self.flip[a] {
                self.dims[a] - 1 - v[a]
            } else {
                v[a]
            };
        }
        o
    }

    /// A study box (both corners inside) in the input storage.
    pub fn box_back(&self, lo: [usize; 3], hi: [usize; 3]) -> ([usize; 3], [usize; 3]) {
        let (a, b) = (self.voxel_back(lo), self.voxel_back(hi));
        (
            [0, 1, 2].map(|i| a[i].min(b[i])),
            [0, 1, 2].map(|i| a[i].max(b[i])),
        )
    }

    /// Study voxel indices (of the study's dims) as sorted input indices.
    pub fn indices_back(&self, voxels: &[usize]) -> Vec<usize> {
        let mut out: Vec<usize> = voxels
            .iter()
            .map(|&i| {
                let v = self.voxel_back(crate::volume::grid_ijk(self.dims, i));
                self.input.index(v[0], v[1], v[2])
            })
            .collect();
        out.sort_unstable();
        out
    }

    fn inverse_perm(&self) -> [usize; 3] {
        let mut inv = [0; 3];
        for a in 0..3 {
            inv[self.perm[a]] = a;
        }
        inv
    }

    fn inverse_flip(&self) -> [bool; 3] {
        let inv = self.inverse_perm();
        [0, 1, 2].map(|b| self.flip[inv[b]])
    }
}

/// The (perm, flip) of `reoriented` that puts a scan of geometry `g` in the study storage.
fn canonical(g: &Geometry) -> ([usize; 3], [bool; 3]) {
    let frame = PatientFrame::of(g);
    let mut perm = [0; 3];
    let mut flip = [false; 3];
    for (b, dir) in [DVec3::X, DVec3::Y, DVec3::Z].into_iter().enumerate() {
        let (a, sign) = frame.nearest_axis(dir);
        perm[b] = a;
        flip[b] = sign < 0;
    }
    let mut sorted = perm;
    sorted.sort_unstable();
    if sorted == [0, 1, 2] {
        return (perm, flip);
    }
    let (axial, _) = frame.nearest_axis(DVec3::Z);
    let mut perm = [0, 1, 2];
    perm.swap(axial, 2);
    (perm, [false; 3])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scan stored upside down and transposed: its study storage runs along L, P, S, and
    /// every map there and back is the identity.
    #[test]
    fn study_storage_runs_along_the_patient_and_maps_back() {
        let mut g = Geometry::new([4, 5, 6], [0.5, 0.7, 2.0], [1.0, 2.0, 3.0]).unwrap();
        // i runs posterior, j left, k inferior.
        g.direction = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]];
        let v = Volume::from_vec(g.clone(), (0..120).collect::<Vec<i32>>()).unwrap();
        let s = Storage::of(&g);
        assert!(!s.is_identity());
        let study = s.to_study(&v).unwrap();
        let m = study.geometry().direction_mat();
        for a in 0..3 {
            assert!((m.col(a)[a] - 1.0).abs() < 1e-12, "axis {a} of {m:?}");
        }
        let back = s.to_input(&study).unwrap();
        assert_eq!(back.data(), v.data());
        assert_eq!(back.geometry().dims, g.dims);
        for idx in [0usize, 7, 63, 119] {
            let sv = study.geometry().ijk(idx);
            let iv = s.voxel_back(sv);
            assert_eq!(s.voxel_in(iv), sv);
            assert_eq!(v.data()[g.index(iv[0], iv[1], iv[2])], study.data()[idx]);
            let p = DVec3::new(
                sv[0] as f64 * study.spacing()[0],
                sv[1] as f64 * study.spacing()[1],
                sv[2] as f64 * study.spacing()[2],
            );
            let q = s.mm_back(p.to_array());
            let want = [0, 1, 2].map(|a| iv[a] as f64 * g.spacing[a]);
            assert!((DVec3::from_array(q) - DVec3::from_array(want)).length() < 1e-9);
            assert!((s.mm_in(DVec3::from_array(q)) - p).length() < 1e-9);
        }
    }
}
