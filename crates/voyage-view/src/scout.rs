//! The scout's picture (paper §5): the whole colon from outside, semi-transparent, with the
//! centerline over it, drawn on the CPU. The window's scout panel orbits it, picks on it
//! and draws the markers and the submarine; what it shows is made here, with no window
//! toolkit.
//!
//! The surface drawn is the study's mesh decimated by vertex clustering (a few mm): the
//! scout shows shape, not mucosa, and tens of thousands of triangles blend fast on any
//! renderer, where the full mesh (over a million) would not. It is alpha-blended over the
//! panel's colour into an opaque image, cropped to what the colon covers, which the window
//! redraws only when the view changes and shows pixel for pixel: it needs no depth buffer
//! and costs little per frame while the submarine flies.

use std::collections::HashMap;

use glam::{DMat3, DVec3, Vec2};
use voyage_core::Mesh;

use crate::{coverage::Coverage, mesh::CellMesh, rgba::Rgba};

/// The colon's surface at scout detail, in volume-local mm.
pub struct ScoutMesh {
    pub positions: Vec<DVec3>,
    pub triangles: Vec<[u32; 3]>,
    /// Per triangle, unit.
    pub normals: Vec<DVec3>,
    pub center: DVec3,
    pub radius: f64,
    /// The scout vertex (cluster) of each surface vertex.
    pub vertex_cluster: Vec<u32>,
}

impl ScoutMesh {
    /// Clusters `mesh`'s vertices on a grid of `cell_mm` and keeps the triangles whose
    /// corners land in three different clusters.
    pub fn new(mesh: &Mesh, cell_mm: f64) -> Self {
        let mut cluster: HashMap<[i32; 3], u32> = HashMap::new();
        let mut sums: Vec<(DVec3, u32)> = Vec::new();
        let mut vertex_cluster = Vec::with_capacity(mesh.positions.len());
        for p in &mesh.positions {
            let p = DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            let key = (p / cell_mm).floor().as_ivec3().to_array();
            let id = *cluster.entry(key).or_insert_with(|| {
                sums.push((DVec3::ZERO, 0));
                sums.len() as u32 - 1
            });
            sums[id as usize].0 += p;
            sums[id as usize].1 += 1;
            vertex_cluster.push(id);
        }
        let positions: Vec<DVec3> = sums.iter().map(|(s, n)| *s / (*n).max(1) as f64).collect();
        let mut triangles = Vec::new();
        let mut normals = Vec::new();
        for t in &mesh.triangles {
            let c = t.map(|v| vertex_cluster[v as usize]);
            if c[0] == c[1] || c[1] == c[2] || c[0] == c[2] {
                continue;
            }
            let [a, b, d] = c.map(|v| positions[v as usize]);
            if let Some(n) = (b - a).cross(d - a).try_normalize() {
                triangles.push(c);
                normals.push(n);
            }
        }
        let (lo, hi) = positions.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        let center = if positions.is_empty() {
            DVec3::ZERO
        } else {
            0.5 * (lo + hi)
        };
        let radius = if positions.is_empty() {
            1.0
        } else {
            (0.5 * (hi - lo).length()).max(1.0)
        };
        ScoutMesh {
            positions,
            triangles,
            normals,
            center,
            radius,
            vertex_cluster,
        }
    }

    /// Per scout vertex (a cluster of surface vertices), the unseen share of its area in
    /// `seen` of the surface `mesh` (the scout colours unseen mucosa by it).
    pub fn unseen_shares(&self, seen: &Coverage, mesh: &CellMesh) -> Vec<f32> {
        let clusters = self.positions.len();
        let mut area = vec![0f32; clusters];
        let mut unseen = vec![0f32; clusters];
        for (t, tri) in mesh.triangles.iter().enumerate() {
            let Some(&c) = self.vertex_cluster.get(tri[0] as usize) else {
                continue;
            };
            let a = seen.area_of(t as u32);
            area[c as usize] += a;
            if !seen.is_seen(t as u32) {
                unseen[c as usize] += a;
            }
        }
        unseen
            .iter()
            .zip(&area)
            .map(|(&u, &a)| if a > 0.0 { u / a } else { 0.0 })
            .collect()
    }
}

/// How the scout is turned: yaw about the body's long axis, then pitch about the screen's
/// right (radians); zoom 1 fits the colon's bounding sphere to the panel's shorter side.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScoutOrbit {
    pub yaw: f64,
    pub pitch: f64,
    pub zoom: f64,
}

impl ScoutOrbit {
    /// From the patient's anterior, the patient's right on the screen's left, head up: the
    /// radiologist's usual first look at a colon.
    pub const FRONT: ScoutOrbit = ScoutOrbit {
        yaw: 0.0,
        pitch: 0.0,
        zoom: 1.0,
    };
}

/// An orthographic view of the scout: screen right, screen up and the viewing direction in
/// local mm, and the map from local mm to the panel's points (y down).
pub struct ScoutProjection {
    pub right: DVec3,
    pub up: DVec3,
    pub forward: DVec3,
    center: DVec3,
    scale: f64,
    origin: Vec2,
}

impl ScoutProjection {
    /// `mesh` seen along `orbit` in a panel of `size` points centred at `centre`.
    /// `anatomy`: the patient's axes (left, posterior, superior) in the volume's local frame.
    pub fn new(
        anatomy: DMat3,
        orbit: ScoutOrbit,
        mesh: &ScoutMesh,
        size: Vec2,
        centre: Vec2,
    ) -> Self {
        let (l, p, s) = (anatomy.x_axis, anatomy.y_axis, anatomy.z_axis);
        let yaw = DMat3::from_axis_angle(s, orbit.yaw);
        let (right0, forward0) = (yaw * l, yaw * p);
        let pitch = DMat3::from_axis_angle(right0, orbit.pitch);
        let (forward, up) = (pitch * forward0, pitch * s);
        let scale = 0.5 * size.x.min(size.y) as f64 / mesh.radius * orbit.zoom;
        ScoutProjection {
            right: right0,
            up,
            forward,
            center: mesh.center,
            scale,
            origin: centre,
        }
    }

    /// Where the local point `p` lies in the panel (points).
    pub fn to_screen(&self, p: DVec3) -> Vec2 {
        let d = p - self.center;
        Vec2::new(
            self.origin.x + (d.dot(self.right) * self.scale) as f32,
            self.origin.y - (d.dot(self.up) * self.scale) as f32,
        )
    }
}

/// The pixels a scout image covers: the panel's top-left corner (points), pixels per point,
/// and its size in pixels.
#[derive(Clone, Copy, Debug)]
pub struct ScoutCanvas {
    pub top_left: Vec2,
    pub ppp: f32,
    pub size: [usize; 2],
}

/// The scout's picture on `canvas`: the decimated surface with the centerline over it (see
/// [`rasterize`]) laid over an opaque `background` (RGB) and cropped to the pixels the colon
/// covers. Returns where the crop's top-left pixel lies on the canvas, and the crop (0 × 0
/// when nothing shows). Faces seen edge-on are more opaque than faces seen head-on: the
/// outline and the folds stand out while the far side shows through (an "x-ray" look).
/// With `unseen` shares per scout vertex, mucosa not yet seen is blue.
pub fn scout_image(
    mesh: &ScoutMesh,
    centerline: &[[f64; 3]],
    unseen: Option<&[f32]>,
    proj: &ScoutProjection,
    canvas: ScoutCanvas,
    background: [u8; 3],
) -> ([usize; 2], Rgba) {
    let buf = rasterize(mesh, centerline, unseen, proj, canvas);
    over_background(&buf, canvas.size, background)
}

/// The premultiplied image `buf` of `size` over an opaque `background`, cropped to the
/// pixels that are not fully transparent: (the crop's top-left pixel, the crop). An image
/// with nothing in it gives a 0 × 0 crop.
fn over_background(buf: &[[f32; 4]], size: [usize; 2], background: [u8; 3]) -> ([usize; 2], Rgba) {
    let [w, h] = size;
    let (mut x0, mut y0, mut x1, mut y1) = (w, h, 0, 0);
    for (i, p) in buf.iter().enumerate() {
        if p[3] > 0.0 {
            let (x, y) = (i % w, i / w);
            (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x + 1), y1.max(y + 1));
        }
    }
    if x0 >= x1 {
        return (
            [0, 0],
            Rgba {
                size: [0, 0],
                bytes: Vec::new(),
            },
        );
    }
    let bg = background.map(|c| c as f32 / 255.0);
    let mut bytes = Vec::with_capacity((x1 - x0) * (y1 - y0) * 4);
    for y in y0..y1 {
        for p in &buf[y * w + x0..y * w + x1] {
            let k = 1.0 - p[3];
            for c in 0..3 {
                bytes.push(((p[c] + bg[c] * k) * 255.0).round().clamp(0.0, 255.0) as u8);
            }
            bytes.push(255);
        }
    }
    (
        [x0, y0],
        Rgba {
            size: [x1 - x0, y1 - y0],
            bytes,
        },
    )
}

/// Alpha-blends the scout's triangles, in the mesh's order, into an image of `canvas`
/// (premultiplied colour, transparent where nothing is), and draws the centerline over them
/// in green (the paper's colour). With `unseen` shares per vertex, mucosa not yet seen is
/// blue, and more opaque, so that it shows through the rest.
fn rasterize(
    mesh: &ScoutMesh,
    centerline: &[[f64; 3]],
    unseen: Option<&[f32]>,
    proj: &ScoutProjection,
    canvas: ScoutCanvas,
) -> Vec<[f32; 4]> {
    let [w, h] = canvas.size;
    let mut buf = vec![[0f32; 4]; w * h];
    let (top_left, ppp) = (canvas.top_left, canvas.ppp);
    let to_px = |p: DVec3| {
        let s = proj.to_screen(p);
        [
            ((s.x - top_left.x) * ppp) as f64,
            ((s.y - top_left.y) * ppp) as f64,
        ]
    };
    for (t, n) in mesh.triangles.iter().zip(&mesh.normals) {
        let facing = n.dot(proj.forward).abs();
        let share = unseen.map_or(0.0, |u| {
            t.iter()
                .map(|&v| u.get(v as usize).copied().unwrap_or(0.0))
                .sum::<f32>()
                / 3.0
        });
        // Unseen where most of the corners' mucosa is: blue, and opaque enough to show.
        let blue = if share >= 0.5 { 1.0 } else { 0.0 };
        let alpha = (0.05 + 0.40 * (1.0 - facing).powi(2)) as f32 * (1.0 - blue) + 0.55 * blue;
        let light = (0.55 + 0.45 * facing) as f32;
        let base = [230.0, 140.0, 120.0].map(|c: f32| c / 255.0);
        let unseen_rgb = [60.0, 120.0, 255.0].map(|c: f32| c / 255.0);
        let rgb = [0, 1, 2].map(|i| base[i] * (1.0 - blue) + unseen_rgb[i] * blue);
        let color = [
            rgb[0] * light * alpha,
            rgb[1] * light * alpha,
            rgb[2] * light * alpha,
            alpha,
        ];
        let v = t.map(|i| to_px(mesh.positions[i as usize]));
        fill_triangle(&mut buf, w, h, v, color);
    }
    let green = [40.0 / 255.0, 220.0 / 255.0, 60.0 / 255.0, 1.0];
    for pair in centerline.windows(2) {
        let (a, b) = (
            to_px(DVec3::from_array(pair[0])),
            to_px(DVec3::from_array(pair[1])),
        );
        stroke(&mut buf, w, h, a, b, (1.5 * ppp) as f64, green);
    }
    buf
}

/// Paints the pixels within `width / 2` of the segment a–b with an opaque colour.
fn stroke(
    buf: &mut [[f32; 4]],
    w: usize,
    h: usize,
    a: [f64; 2],
    b: [f64; 2],
    width: f64,
    c: [f32; 4],
) {
    let r = 0.5 * width.max(1.0);
    let (x0, x1) = (
        (a[0].min(b[0]) - r).floor().max(0.0) as usize,
        ((a[0].max(b[0]) + r).ceil().max(0.0) as usize).min(w),
    );
    let (y0, y1) = (
        (a[1].min(b[1]) - r).floor().max(0.0) as usize,
        ((a[1].max(b[1]) + r).ceil().max(0.0) as usize).min(h),
    );
    let d = [b[0] - a[0], b[1] - a[1]];
    let len2 = (d[0] * d[0] + d[1] * d[1]).max(1e-12);
    for y in y0..y1 {
        for x in x0..x1 {
            let p = [x as f64 + 0.5 - a[0], y as f64 + 0.5 - a[1]];
            let t = ((p[0] * d[0] + p[1] * d[1]) / len2).clamp(0.0, 1.0);
            let (ex, ey) = (p[0] - t * d[0], p[1] - t * d[1]);
            if ex * ex + ey * ey <= r * r {
                buf[y * w + x] = c;
            }
        }
    }
}

/// Blends a premultiplied colour "over" every pixel whose centre lies in the triangle
/// (either winding: the scout shows both sides of the wall).
fn fill_triangle(buf: &mut [[f32; 4]], w: usize, h: usize, v: [[f64; 2]; 3], c: [f32; 4]) {
    let area =
        (v[1][0] - v[0][0]) * (v[2][1] - v[0][1]) - (v[1][1] - v[0][1]) * (v[2][0] - v[0][0]);
    if area.abs() < 1e-12 {
        return;
    }
    let x0 = v
        .iter()
        .map(|p| p[0])
        .fold(f64::INFINITY, f64::min)
        .floor()
        .max(0.0) as usize;
    let x1 = (v
        .iter()
        .map(|p| p[0])
        .fold(f64::NEG_INFINITY, f64::max)
        .ceil()
        .max(0.0) as usize)
        .min(w);
    let y0 = v
        .iter()
        .map(|p| p[1])
        .fold(f64::INFINITY, f64::min)
        .floor()
        .max(0.0) as usize;
    let y1 = (v
        .iter()
        .map(|p| p[1])
        .fold(f64::NEG_INFINITY, f64::max)
        .ceil()
        .max(0.0) as usize)
        .min(h);
    let sign = area.signum();
    let edge = |a: [f64; 2], b: [f64; 2], x: f64, y: f64| {
        ((b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0])) * sign
    };
    for y in y0..y1 {
        let py = y as f64 + 0.5;
        for x in x0..x1 {
            let px = x as f64 + 0.5;
            if edge(v[0], v[1], px, py) >= 0.0
                && edge(v[1], v[2], px, py) >= 0.0
                && edge(v[2], v[0], px, py) >= 0.0
            {
                let d = &mut buf[y * w + x];
                let k = 1.0 - c[3];
                for i in 0..4 {
                    d[i] = c[i] + d[i] * k;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scout_image_is_cropped_and_laid_over_the_background() {
        let bg = [20; 3];
        // 4 × 3, nothing drawn: an empty crop.
        let empty = vec![[0.0f32; 4]; 12];
        assert_eq!(over_background(&empty, [4, 3], bg).1.size, [0, 0]);
        // One opaque red pixel at (1, 1) and one half-transparent white at (2, 2).
        let mut buf = empty.clone();
        buf[4 + 1] = [1.0, 0.0, 0.0, 1.0];
        buf[2 * 4 + 2] = [0.5, 0.5, 0.5, 0.5];
        let (at, img) = over_background(&buf, [4, 3], bg);
        assert_eq!((at, img.size), ([1, 1], [2, 2]));
        let px = |x: usize, y: usize| img.bytes[4 * (y * 2 + x)..][..4].to_vec();
        assert_eq!(px(0, 0), vec![255, 0, 0, 255]);
        // Premultiplied 0.5 over 20: 127.5 + 10 → 138 (rounded), opaque.
        assert_eq!(px(1, 1), vec![138, 138, 138, 255]);
        // Untouched pixels inside the crop show the background.
        assert_eq!(px(1, 0), vec![20, 20, 20, 255]);
    }

    #[test]
    fn vertices_in_one_cell_merge_and_triangles_they_collapse_go() {
        // Triangle 0 spans three cells of 4 mm; triangle 1 has two corners in one cell.
        let mesh = Mesh {
            positions: vec![
                [0.5, 0.5, 0.5],
                [8.5, 0.5, 0.5],
                [0.5, 8.5, 0.5],
                [1.5, 0.5, 0.5],
            ],
            normals: vec![[0.0, 0.0, 1.0]; 4],
            triangles: vec![[0, 1, 2], [0, 3, 1]],
        };
        let scout = ScoutMesh::new(&mesh, 4.0);
        assert_eq!(scout.vertex_cluster, vec![0, 1, 2, 0]);
        assert_eq!(scout.positions[0], DVec3::new(1.0, 0.5, 0.5));
        assert_eq!(scout.triangles, vec![[0, 1, 2]]);
        assert_eq!(scout.normals, vec![DVec3::Z]);
    }

    #[test]
    fn the_front_view_puts_the_patients_right_on_the_left_and_the_head_up() {
        let mesh = Mesh {
            positions: vec![[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 0.0, 10.0]],
            normals: vec![[0.0, 1.0, 0.0]; 3],
            triangles: vec![[0, 1, 2]],
        };
        let scout = ScoutMesh::new(&mesh, 1.0);
        // Local axes are L, P, S: the left (+x) to the screen's right, superior (+z) up.
        let proj = ScoutProjection::new(
            DMat3::IDENTITY,
            ScoutOrbit::FRONT,
            &scout,
            Vec2::new(100.0, 100.0),
            Vec2::new(50.0, 50.0),
        );
        let (a, b, c) = (
            proj.to_screen(DVec3::ZERO),
            proj.to_screen(DVec3::X * 10.0),
            proj.to_screen(DVec3::Z * 10.0),
        );
        assert!(b.x > a.x && (b.y - a.y).abs() < 1e-4);
        assert!(c.y < a.y && (c.x - a.x).abs() < 1e-4);
        assert_eq!(proj.forward, DVec3::Y);
        // The whole triangle drawn: some pixels covered, cropped inside the canvas.
        let canvas = ScoutCanvas {
            top_left: Vec2::ZERO,
            ppp: 1.0,
            size: [100, 100],
        };
        let (at, img) = scout_image(&scout, &[], None, &proj, canvas, [0; 3]);
        assert!(img.size[0] > 10 && img.size[1] > 10);
        assert!(at[0] + img.size[0] <= 100 && at[1] + img.size[1] <= 100);
    }
}
