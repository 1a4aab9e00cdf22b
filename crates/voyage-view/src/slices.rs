//! Reslicing the CT for the window's slice panel (paper §5): axial, coronal and sagittal
//! images laid out the way radiologists read them (the patient's right on the screen's
//! left; anterior up on axial slices, head up on the others) whatever way the patient lay or
//! the data is stored, under a window / level, showing the original CT or the cleansed one
//! with cleansing's voxels outlined on request. The panel itself (presets, drag, scroll,
//! clicks, the letters drawn) is the window's; this is what it shows, with no window toolkit.

use std::collections::HashMap;

use glam::DVec3;
use voyage_core::{Cleansing, Geometry, Volume};

use crate::rgba::Rgba;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Plane {
    Axial,
    Coronal,
    Sagittal,
}

impl Plane {
    pub const ALL: [Plane; 3] = [Plane::Axial, Plane::Coronal, Plane::Sagittal];
    pub fn name(self) -> &'static str {
        match self {
            Plane::Axial => "axial",
            Plane::Coronal => "coronal",
            Plane::Sagittal => "sagittal",
        }
    }

    /// The patient's side at the image's left, right, top and bottom edges, as
    /// [`SliceLayout::of`] puts it in the standard display whatever way the patient lay or
    /// the data is stored: right on the left, anterior up on axial slices, head up on the
    /// others.
    pub fn edge_letters(self) -> [&'static str; 4] {
        match self {
            Plane::Axial => ["R", "L", "A", "P"],
            Plane::Coronal => ["R", "L", "S", "I"],
            Plane::Sagittal => ["A", "P", "S", "I"],
        }
    }
}

/// How a plane's image maps to voxel indices: which index axis runs along the screen's x
/// and y (and whether reversed), and which is fixed.
#[derive(Clone, Copy, Debug)]
pub struct SliceLayout {
    pub x: (usize, bool),
    pub y: (usize, bool),
    pub fixed: usize,
}

/// For patient axis a (L, P, S): the index axis nearest to it and whether the index grows
/// with the patient coordinate.
fn patient_axes(g: &Geometry) -> [(usize, bool); 3] {
    let d = g.direction_mat();
    std::array::from_fn(|a| {
        let row = [d.x_axis[a], d.y_axis[a], d.z_axis[a]];
        let c = (0..3)
            .max_by(|&i, &j| row[i].abs().total_cmp(&row[j].abs()))
            .unwrap_or(a);
        (c, row[c] >= 0.0)
    })
}

impl SliceLayout {
    /// `plane` of a volume of geometry `g` in the standard display.
    pub fn of(g: &Geometry, plane: Plane) -> Self {
        let [l, p, s] = patient_axes(g);
        // (axis, patient coordinate grows toward screen +x / +y (down)).
        let along = |(c, grows): (usize, bool), want_growing: bool| (c, grows != want_growing);
        match plane {
            Plane::Axial => SliceLayout {
                x: along(l, true),
                y: along(p, true),
                fixed: s.0,
            },
            Plane::Coronal => SliceLayout {
                x: along(l, true),
                y: along(s, false),
                fixed: p.0,
            },
            Plane::Sagittal => SliceLayout {
                x: along(p, true),
                y: along(s, false),
                fixed: l.0,
            },
        }
    }

    /// The voxels along the image's width and height, of a volume of `dims`.
    pub fn image_voxels(&self, dims: [usize; 3]) -> [usize; 2] {
        [dims[self.x.0], dims[self.y.0]]
    }

    /// Where the centre of the voxel with indices `ix` (along the image's x axis) and `iy`
    /// (along its y axis) lies in the image, as a fraction of its width and height.
    pub fn fraction_of(&self, dims: [usize; 3], ix: f64, iy: f64) -> [f32; 2] {
        let [nx, ny] = self.image_voxels(dims);
        let u = if self.x.1 { nx as f64 - 1.0 - ix } else { ix };
        let v = if self.y.1 { ny as f64 - 1.0 - iy } else { iy };
        [
            ((u + 0.5) / nx as f64) as f32,
            ((v + 0.5) / ny as f64) as f32,
        ]
    }

    /// The voxel (indices, the nearest centre) under the point at `fraction` of the
    /// image's width and height on slice `fixed`: a point given back to segmentation lies
    /// in the voxel the user saw.
    pub fn voxel_at(&self, dims: [usize; 3], fraction: [f32; 2], fixed: usize) -> DVec3 {
        let [nx, ny] = self.image_voxels(dims);
        let u = fraction[0] as f64 * nx as f64 - 0.5;
        let v = fraction[1] as f64 * ny as f64 - 0.5;
        let mut ijk = [0.0; 3];
        ijk[self.x.0] = if self.x.1 { nx as f64 - 1.0 - u } else { u };
        ijk[self.y.0] = if self.y.1 { ny as f64 - 1.0 - v } else { v };
        ijk[self.fixed] = fixed as f64;
        DVec3::from_array(ijk).round()
    }
}

/// How a slice is shown: window / level (HU), size in pixels, and cleansing's changes in its
/// plane (voxel index → cleansed HU), shown in place of the CT's values and/or outlined.
pub struct SliceShading<'a> {
    pub window: f64,
    pub level: f64,
    pub size: [usize; 2],
    pub changes: Option<&'a HashMap<usize, i16>>,
    pub cleansed: bool,
    pub outline: bool,
}

/// Cleansing's changes in the plane where index axis `axis` is `at`.
pub fn changes_in_plane(
    c: &Cleansing,
    dims: [usize; 3],
    axis: usize,
    at: usize,
) -> HashMap<usize, i16> {
    let stride = [1, dims[0], dims[0] * dims[1]][axis];
    c.voxels()
        .iter()
        .zip(c.values())
        .filter(|&(&v, _)| (v as usize / stride) % dims[axis] == at)
        .map(|(&v, &h)| (v as usize, h))
        .collect()
}

/// Outline colour of the cleansed voxels.
const OUTLINE: [u8; 4] = [0, 210, 255, 255];

/// The grey image of one slice under a window / level, `size` pixels (the slice's
/// orientation on screen), each pixel the voxel under its centre (no interpolation, as a
/// slice viewer with interpolation off: a mask stays two-valued, and a slice shown smaller
/// than the CT reads one voxel per pixel, not all of them).
pub fn slice_image(ct: &Volume<i16>, lay: SliceLayout, fixed: usize, shown: &SliceShading) -> Rgba {
    let size = shown.size;
    let dims = ct.dims();
    let stride = [1, dims[0], dims[0] * dims[1]];
    // Per image column (row): the offset in the data of the voxels under it.
    let offsets = |m: usize, (axis, reversed): (usize, bool)| -> Vec<usize> {
        let n = dims[axis];
        (0..m)
            .map(|u| {
                let c = voxel_under(u, n, m);
                (if reversed { n - 1 - c } else { c }) * stride[axis]
            })
            .collect()
    };
    let (xs, ys) = (offsets(size[0], lay.x), offsets(size[1], lay.y));
    let data = ct.data();
    let base = fixed * stride[lay.fixed];
    let lo = (shown.level - 0.5 * shown.window) as f32;
    let k = (255.0 / shown.window.max(1.0)) as f32;
    let changed = |v: usize| shown.changes.and_then(|c| c.get(&v).copied());
    let mut bytes = Vec::with_capacity(size[0] * size[1] * 4);
    for (y, &r) in ys.iter().enumerate() {
        let row = base + r;
        for (x, &c) in xs.iter().enumerate() {
            let v = row + c;
            let new = changed(v);
            // A changed voxel whose neighbour on screen is not: the outline.
            let edge = shown.outline
                && new.is_some()
                && [
                    (x.wrapping_sub(1), y),
                    (x + 1, y),
                    (x, y.wrapping_sub(1)),
                    (x, y + 1),
                ]
                .iter()
                .any(|&(a, b)| {
                    a >= size[0] || b >= size[1] || changed(base + ys[b] + xs[a]).is_none()
                });
            if edge {
                bytes.extend_from_slice(&OUTLINE);
                continue;
            }
            let hu = match new {
                Some(h) if shown.cleansed => h,
                _ => data[v],
            };
            let g = ((hu as f32 - lo) * k).clamp(0.0, 255.0) as u8;
            bytes.extend_from_slice(&[g, g, g, 255]);
        }
    }
    Rgba { size, bytes }
}

/// The voxel (of `n` along an axis) under the centre of pixel `u` of `m` pixels spanning
/// the `n` voxels.
fn voxel_under(u: usize, n: usize, m: usize) -> usize {
    (((2 * u + 1) * n) / (2 * m)).min(n - 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identity_geometry_reads_radiologically() {
        let g = Geometry::new([4, 5, 6], [1.0; 3], [0.0; 3]).unwrap();
        // Axial: L grows to the screen's right (patient's right on the left), P downward.
        let a = SliceLayout::of(&g, Plane::Axial);
        assert_eq!((a.x, a.y, a.fixed), ((0, false), (1, false), 2));
        // Coronal and sagittal: head up, so k runs upward (reversed on screen).
        let c = SliceLayout::of(&g, Plane::Coronal);
        assert_eq!((c.x, c.y, c.fixed), ((0, false), (2, true), 1));
        let s = SliceLayout::of(&g, Plane::Sagittal);
        assert_eq!((s.x, s.y, s.fixed), ((1, false), (2, true), 0));
    }

    #[test]
    fn flipped_axes_are_undone() {
        // A RAS-stored volume: i → right (−L), j → anterior (−P).
        let mut g = Geometry::new([4, 5, 6], [1.0; 3], [0.0; 3]).unwrap();
        g.set_direction_mat(glam::DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0)));
        let a = SliceLayout::of(&g, Plane::Axial);
        assert_eq!((a.x, a.y), ((0, true), (1, true)));
    }

    #[test]
    fn a_voxel_centre_and_the_voxel_under_it_agree() {
        // Coronal of 4 × 5 × 6: x = i, y = k reversed; the slice is j = 3.
        let g = Geometry::new([4, 5, 6], [1.0; 3], [0.0; 3]).unwrap();
        let lay = SliceLayout::of(&g, Plane::Coronal);
        let dims = g.dims;
        assert_eq!(lay.image_voxels(dims), [4, 6]);
        let f = lay.fraction_of(dims, 1.0, 5.0);
        assert_eq!(f, [0.375, (0.5f64 / 6.0) as f32]);
        assert_eq!(lay.voxel_at(dims, f, 3), DVec3::new(1.0, 3.0, 5.0));
        // Anywhere inside the pixel picks the same voxel.
        let inside = [f[0] + 0.1 / 4.0, f[1] - 0.1 / 6.0];
        assert_eq!(lay.voxel_at(dims, inside, 3), DVec3::new(1.0, 3.0, 5.0));
    }

    /// A volume whose voxel (i, j, k) holds i + 10 j + 100 k.
    fn numbered(dims: [usize; 3]) -> Volume<i16> {
        let g = Geometry::new(dims, [1.0; 3], [0.0; 3]).unwrap();
        let data = (0..dims[2])
            .flat_map(|k| {
                (0..dims[1])
                    .flat_map(move |j| (0..dims[0]).map(move |i| (i + 10 * j + 100 * k) as i16))
            })
            .collect();
        Volume::from_vec(g, data).unwrap()
    }

    /// The value a grey pixel stands for under window 255, level 127.5 (grey = value).
    fn value(img: &Rgba, x: usize, y: usize) -> i16 {
        let p = &img.bytes[4 * (y * img.size[0] + x)..][..4];
        assert_eq!(
            (p[0], p[1], p[2], p[3]),
            (p[0], p[0], p[0], 255),
            "grey and opaque"
        );
        p[0] as i16
    }

    #[test]
    fn each_pixel_shows_the_voxel_under_its_centre() {
        // Same size: every voxel once. Half size: voxels 1, 3, 5, ... Double: each twice.
        assert_eq!(
            (0..6).map(|u| voxel_under(u, 6, 6)).collect::<Vec<_>>(),
            vec![0, 1, 2, 3, 4, 5]
        );
        assert_eq!(
            (0..3).map(|u| voxel_under(u, 6, 3)).collect::<Vec<_>>(),
            vec![1, 3, 5]
        );
        assert_eq!(
            (0..4).map(|u| voxel_under(u, 2, 4)).collect::<Vec<_>>(),
            vec![0, 0, 1, 1]
        );
        assert_eq!(voxel_under(0, 5, 1), 2);
    }

    #[test]
    fn slice_images_read_the_fixed_plane_in_screen_order() {
        let ct = numbered([6, 5, 2]);
        let g = ct.geometry().clone();
        // Axial slice k = 1 at full size: x = i, y = j, values i + 10 j + 100.
        let plain = |size| SliceShading {
            window: 255.0,
            level: 127.5,
            size,
            changes: None,
            cleansed: false,
            outline: false,
        };
        let a = slice_image(&ct, SliceLayout::of(&g, Plane::Axial), 1, &plain([6, 5]));
        for (x, y) in [(0, 0), (5, 0), (2, 3), (5, 4)] {
            assert_eq!(value(&a, x, y), (x + 10 * y + 100) as i16);
        }
        // Coronal slice j = 2: x = i, y = k reversed (head up): the top row is k = 1.
        let c = slice_image(&ct, SliceLayout::of(&g, Plane::Coronal), 2, &plain([6, 2]));
        assert_eq!(value(&c, 4, 0), 4 + 20 + 100);
        assert_eq!(value(&c, 4, 1), 4 + 20);
        // Sagittal slice i = 3 at half width: x = j under each pixel's centre (1, 3), y = k reversed.
        let s = slice_image(&ct, SliceLayout::of(&g, Plane::Sagittal), 3, &plain([2, 2]));
        assert_eq!(value(&s, 0, 0), 3 + 10 + 100);
        assert_eq!(value(&s, 1, 1), 3 + 30);
    }
}
