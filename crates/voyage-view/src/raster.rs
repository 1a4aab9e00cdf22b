//! The CPU reference rasterizer: perspective, a depth buffer and a triangle-id buffer, and
//! endoscope lighting per vertex (Gouraud, as the GPU renderer's vertex stage does; with
//! voxel-sized triangles it is indistinguishable from lighting every pixel, at a fraction
//! of the cost). It is the visibility oracle and the renderer when no GPU
//! exists, so two properties matter more than speed:
//!
//! - **Order independence.** A pixel keeps the nearest triangle covering its centre, ties
//!   going to the smaller id, and whether a triangle covers a pixel (and at what depth) is a
//!   function of that triangle and the camera alone. So the id buffer is the same whatever
//!   order the cells are drawn in, and culling changes it only if it leaves out a triangle
//!   that wins somewhere: exactly what the exactness tests look for.
//! - **Shared edges are exact.** Edge functions are computed from the edge's endpoints in a
//!   canonical order and negated for the other direction, with a top-left rule, so two
//!   triangles sharing an edge never both take, or both miss, a pixel centre on it.
//!
//! Back faces are culled: the camera is always inside the closed surface (the navigation's
//! safe set), where every first hit is a face whose normal points back into the lumen.

use std::cell::RefCell;

use glam::{DVec3, Vec3};

use super::{mesh::CellMesh, shading::Lighting};
use voyage_nav::Camera;

/// Marks a pixel no triangle covers.
pub const NO_TRIANGLE: u32 = u32::MAX;

/// Bounding boxes at least this wide (pixels) are scanned only between the edges' crossings
/// of each row; narrower ones are tested pixel by pixel.
const SPAN_MIN_WIDTH: i64 = 8;

/// Depth (mm along the view axis) below which points are clipped away.
const MIN_NEAR_MM: f64 = 1e-4;

/// One pixel of a [`Frame`]: kept together so that the depth test and the writes after it
/// touch one cache line, not three.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pixel {
    /// Inverse depth (mm⁻¹) of the nearest triangle; 0 where none.
    pub inv_depth: f32,
    /// Its draw index in the [`CellMesh`], or [`NO_TRIANGLE`].
    pub id: u32,
    /// The colour: the vertices' lit colours interpolated at the pixel centre
    /// (perspective-correct, as a GPU interpolates varyings).
    pub rgb: [u8; 3],
}

const EMPTY: Pixel = Pixel {
    inv_depth: 0.0,
    id: NO_TRIANGLE,
    rgb: [0; 3],
};

/// What the rasterizer writes, per pixel, row-major, top row first.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<Pixel>,
}

impl Frame {
    pub fn new(width: u32, height: u32) -> Self {
        Frame {
            width,
            height,
            pixels: vec![EMPTY; width as usize * height as usize],
        }
    }

    pub fn clear(&mut self) {
        self.pixels.fill(EMPTY);
    }

    pub fn id(&self, i: usize) -> u32 {
        self.pixels[i].id
    }

    pub fn ids(&self) -> impl Iterator<Item = u32> + '_ {
        self.pixels.iter().map(|p| p.id)
    }

    /// Pixels whose triangle differs from `other`'s.
    pub fn id_differences(&self, other: &Frame) -> usize {
        self.pixels
            .iter()
            .zip(&other.pixels)
            .filter(|(a, b)| a.id != b.id)
            .count()
    }

    /// Pixels some triangle covers.
    pub fn covered(&self) -> usize {
        self.pixels.iter().filter(|p| p.id != NO_TRIANGLE).count()
    }

    /// All its rows, to draw into.
    pub fn rows(&mut self) -> Rows<'_> {
        Rows {
            width: self.width as usize,
            first: 0,
            last: self.height as i64 - 1,
            pixels: &mut self.pixels,
        }
    }

    /// Its rows cut into `n` bands (at most one per row), top first, as even as the rows
    /// allow: the frame drawn band by band, each by a worker of its own.
    pub fn bands(&mut self, n: usize) -> Vec<Rows<'_>> {
        let (w, h) = (self.width as usize, self.height as usize);
        let n = n.clamp(1, h.max(1));
        let mut rest: &mut [Pixel] = &mut self.pixels;
        let mut bands = Vec::with_capacity(n);
        let mut first = 0;
        for b in 0..n {
            let end = h * (b + 1) / n;
            let (band, tail) = rest.split_at_mut((end - first) * w);
            bands.push(Rows {
                width: w,
                first: first as i64,
                last: end as i64 - 1,
                pixels: band,
            });
            (rest, first) = (tail, end);
        }
        bands
    }
}

/// Rows `first..=last` of a [`Frame`], full width: what a rasterizer draws into. A triangle
/// drawn into a band writes exactly the pixels of those rows that it writes in the whole
/// frame, so bands drawn apart make the frame drawn whole.
pub struct Rows<'a> {
    width: usize,
    first: i64,
    last: i64,
    pixels: &'a mut [Pixel],
}

impl Rows<'_> {
    pub fn first(&self) -> i64 {
        self.first
    }

    pub fn last(&self) -> i64 {
        self.last
    }

    pub fn width(&self) -> usize {
        self.width
    }

    /// The pixel at column x of row y (a row of this band).
    #[inline]
    pub fn pixel(&self, x: i64, y: i64) -> &Pixel {
        &self.pixels[(y - self.first) as usize * self.width + x as usize]
    }

    #[inline]
    fn pixel_mut(&mut self, x: i64, y: i64) -> &mut Pixel {
        &mut self.pixels[(y - self.first) as usize * self.width + x as usize]
    }
}

/// A camera as the rasterizer uses it: eye, view axes, focal length in pixels.
#[derive(Clone, Copy, Debug)]
pub struct View {
    pub eye: DVec3,
    /// Screen right, screen up and forward (the view direction), unit vectors.
    pub right: DVec3,
    pub up: DVec3,
    pub forward: DVec3,
    pub width: u32,
    pub height: u32,
    /// Pixels per unit of x/depth (and y/depth): height / (2 tan(fov/2)).
    pub focal: f64,
    pub near: f64,
}

impl View {
    pub fn new(camera: &Camera, width: u32, height: u32) -> Self {
        let p = &camera.pose;
        View {
            eye: p.position,
            right: -p.x_body(),
            up: p.y_body(),
            forward: p.z_body(),
            width,
            height,
            focal: height as f64 / (2.0 * camera.tan_half_fov()),
            near: camera.near_mm.max(MIN_NEAR_MM),
        }
    }

    /// Eye coordinates (right, up, depth) of a volume-local point.
    #[inline]
    pub fn to_eye(&self, p: DVec3) -> DVec3 {
        let v = p - self.eye;
        DVec3::new(v.dot(self.right), v.dot(self.up), v.dot(self.forward))
    }

    /// Continuous pixel coordinates (top-left origin) of an eye point in front of the camera.
    #[inline]
    pub fn project(&self, e: DVec3) -> (f64, f64) {
        let s = self.focal / e.z;
        (
            0.5 * self.width as f64 + e.x * s,
            0.5 * self.height as f64 - e.y * s,
        )
    }

    /// The (unnormalised) direction of the ray through the centre of pixel (x, y).
    #[inline]
    pub fn pixel_direction(&self, x: u32, y: u32) -> DVec3 {
        let sx = (x as f64 + 0.5 - 0.5 * self.width as f64) / self.focal;
        let sy = (0.5 * self.height as f64 - (y as f64 + 0.5)) / self.focal;
        self.forward + sx * self.right + sy * self.up
    }

    /// Distance from the eye (mm) of what pixel (x, y) shows at inverse depth `inv_depth`:
    /// the depth along the view axis times the ray's length per unit depth.
    #[inline]
    pub fn pixel_distance(&self, x: u32, y: u32, inv_depth: f32) -> f64 {
        let sx = (x as f64 + 0.5 - 0.5 * self.width as f64) / self.focal;
        let sy = (0.5 * self.height as f64 - (y as f64 + 0.5)) / self.focal;
        (1.0 + sx * sx + sy * sy).sqrt() / inv_depth as f64
    }
}

/// Pixel centres a cell may show at: columns `x0..=x1` of rows `y0..=y1` (empty when either
/// range is).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct ScreenRect {
    pub x0: i64,
    pub x1: i64,
    pub y0: i64,
    pub y1: i64,
}

impl ScreenRect {
    pub fn full(view: &View) -> Self {
        ScreenRect {
            x0: 0,
            x1: view.width as i64 - 1,
            y0: 0,
            y1: view.height as i64 - 1,
        }
    }

    /// The whole width of `rows`.
    pub fn of_rows(view: &View, rows: &Rows) -> Self {
        ScreenRect {
            y0: rows.first,
            y1: rows.last,
            ..ScreenRect::full(view)
        }
    }

    /// The least rectangle holding all of `rects` (empty when they all are).
    pub fn around(rects: &[ScreenRect]) -> Self {
        rects.iter().filter(|r| !r.is_empty()).fold(
            ScreenRect {
                x0: i64::MAX,
                x1: i64::MIN,
                y0: i64::MAX,
                y1: i64::MIN,
            },
            |a, r| ScreenRect {
                x0: a.x0.min(r.x0),
                x1: a.x1.max(r.x1),
                y0: a.y0.min(r.y0),
                y1: a.y1.max(r.y1),
            },
        )
    }

    pub fn is_empty(&self) -> bool {
        self.x0 > self.x1 || self.y0 > self.y1
    }
}

/// Slack (pixels) added around projected outlines: rounding must never drop a pixel centre
/// that lies on an outline.
pub(crate) const SLACK_PX: f64 = 1e-3;
/// ... and around projected boxes, wider: the rasterizer transforms vertices in f32, the
/// box test in f64.
const BOX_SLACK_PX: f64 = 1e-2;

/// Pixel indices whose centres (i + 0.5) lie in [a, b], clamped to the screen.
pub(crate) fn centres(a: f64, b: f64, size: u32) -> (i64, i64) {
    let lo = (a - 0.5 - SLACK_PX).ceil().max(0.0);
    let hi = (b - 0.5 + SLACK_PX).floor().min(size as f64 - 1.0);
    if lo > hi || hi < 0.0 {
        (1, 0)
    } else {
        (lo as i64, hi as i64)
    }
}

impl View {
    /// Whether a box (volume-local mm, `lo`–`hi`) may hold a triangle that covers a pixel
    /// centre of `rect`: false only when the box lies wholly behind the near plane (no
    /// triangle of it is drawn), or wholly in front of it with its projection's bounding
    /// rectangle holding no centre of `rect` (a projected triangle lies within its box's
    /// projected corners).
    pub fn box_may_show(&self, lo: [f32; 3], hi: [f32; 3], rect: &ScreenRect) -> bool {
        if rect.is_empty() {
            return false;
        }
        let (mut behind, mut x0, mut x1, mut y0, mut y1) = (
            0,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        for k in 0..8 {
            let c = DVec3::new(
                if k & 1 == 0 { lo[0] } else { hi[0] } as f64,
                if k & 2 == 0 { lo[1] } else { hi[1] } as f64,
                if k & 4 == 0 { lo[2] } else { hi[2] } as f64,
            );
            let e = self.to_eye(c);
            if e.z < self.near {
                behind += 1;
                continue;
            }
            let (x, y) = self.project(e);
            (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
        }
        match behind {
            8 => false,
            0 => {
                let (c0, c1) = centres(x0 - BOX_SLACK_PX, x1 + BOX_SLACK_PX, self.width);
                let (r0, r1) = centres(y0 - BOX_SLACK_PX, y1 + BOX_SLACK_PX, self.height);
                c0.max(rect.x0) <= c1.min(rect.x1) && r0.max(rect.y0) <= r1.min(rect.y1)
            }
            // Across the near plane: its projection is unbounded.
            _ => true,
        }
    }
}

/// The eye transform in f32, relative to the eye, for the per-triangle work.
#[derive(Clone, Copy)]
struct EyeXf {
    eye: Vec3,
    right: Vec3,
    up: Vec3,
    forward: Vec3,
}

impl EyeXf {
    fn new(view: &View) -> Self {
        EyeXf {
            eye: view.eye.as_vec3(),
            right: view.right.as_vec3(),
            up: view.up.as_vec3(),
            forward: view.forward.as_vec3(),
        }
    }
}

/// A vertex on screen: pixel coordinates and inverse depth.
#[derive(Clone, Copy)]
struct ScreenVertex {
    x: f64,
    y: f64,
    w: f64,
}

/// A vertex transformed for one frame: relative to the eye (world axes, f32, for the
/// facing test), in eye coordinates, and on screen (when in front of the near plane).
#[derive(Clone)]
struct Vertex {
    rel: Vec3,
    eye: DVec3,
    normal: Vec3,
    /// Lit colour (display values 0..1), computed the first time a triangle that covers a
    /// pixel needs it (NaN until then): most vertices of a drawn cell face away or fall
    /// between pixel centres.
    color: std::cell::Cell<Vec3>,
    screen: ScreenVertex,
}

/// Draws cells into a frame: the rasterizer proper.
pub struct Rasterizer<'a> {
    mesh: &'a CellMesh,
    view: View,
    xf: EyeXf,
    /// None: ids and depths only ([`Rasterizer::ids_only`]), every colour black.
    shading: Option<&'a Shading>,
    /// The current chunk's transformed vertices.
    scratch: RefCell<Vec<Vertex>>,
    /// Chunks wholly farther from the eye than this (mm) are left out
    /// ([`Rasterizer::within_reach`]).
    reach_mm: Option<f32>,
}

impl Clone for Rasterizer<'_> {
    /// The same drawing, with scratch memory of its own.
    fn clone(&self) -> Self {
        Rasterizer {
            scratch: RefCell::new(Vec::new()),
            ..*self
        }
    }
}

impl<'a> Rasterizer<'a> {
    /// Draws `mesh` as `view` sees it, lit by `shading` (made once for many frames).
    pub fn new(mesh: &'a CellMesh, view: View, shading: &'a Shading) -> Self {
        Rasterizer {
            mesh,
            xf: EyeXf::new(&view),
            view,
            shading: Some(shading),
            scratch: RefCell::new(Vec::new()),
            reach_mm: None,
        }
    }

    /// Draws the ids and depths alone, every colour black: what coverage reads. The same
    /// pixels win as in a shaded frame; lighting costs about a third of a reading's frame.
    pub fn ids_only(mesh: &'a CellMesh, view: View) -> Self {
        Rasterizer {
            mesh,
            xf: EyeXf::new(&view),
            view,
            shading: None,
            scratch: RefCell::new(Vec::new()),
            reach_mm: None,
        }
    }

    /// Leaves out the chunks that lie wholly farther than `mm` from the eye. What a pixel
    /// nearer than `mm` shows is the same: a chunk left out could only win pixels farther
    /// than that, and hides nothing nearer. Coverage reads no pixel beyond its reading
    /// distance, and down a wide colon most of a frame's triangles lie beyond it.
    pub fn within_reach(mut self, mm: f64) -> Self {
        self.reach_mm = Some(mm as f32);
        self
    }

    /// Whether chunk `k` may hold a point within the reach.
    fn in_reach(&self, k: usize) -> bool {
        let Some(reach) = self.reach_mm else {
            return true;
        };
        let c = &self.mesh.chunks[k];
        let eye = self.xf.eye;
        let lo = Vec3::from_array(c.lo);
        let hi = Vec3::from_array(c.hi);
        let gap = (lo - eye).max(eye - hi).max(Vec3::ZERO);
        gap.length_squared() <= reach * reach
    }

    pub fn view(&self) -> &View {
        &self.view
    }

    /// The triangles of `cell` that [`Self::draw_cell_within`] draws within any of `rects`,
    /// or with None that [`Self::draw_cell`] draws, each counted once.
    pub fn triangles_in(&self, cell: u32, rects: Option<&[ScreenRect]>) -> usize {
        let mesh = self.mesh;
        if !mesh.is_indexed() {
            return mesh.cell_ranges[cell as usize].len();
        }
        self.chunks_to_draw(cell, rects)
            .map(|k| mesh.chunks[k].triangles.len())
            .sum()
    }

    /// The chunks of `cell` (indexed meshes) that may show a pixel centre within any of
    /// `rects` (all of them with None), less those beyond the reach.
    fn chunks_to_draw<'r>(
        &'r self,
        cell: u32,
        rects: Option<&'r [ScreenRect]>,
    ) -> impl Iterator<Item = usize> + 'r {
        self.mesh.cell_chunks[cell as usize]
            .clone()
            .map(|k| k as usize)
            .filter(move |&k| {
                let c = &self.mesh.chunks[k];
                self.in_reach(k)
                    && rects
                        .is_none_or(|rs| rs.iter().any(|r| self.view.box_may_show(c.lo, c.hi, r)))
            })
    }

    /// Draws every triangle of a cell; returns how many triangles that was.
    pub fn draw_cell(&self, frame: &mut Rows, cell: u32) -> usize {
        let mesh = self.mesh;
        if !mesh.is_indexed() {
            let range = mesh.cell_ranges[cell as usize].clone();
            for id in range.clone() {
                let t = mesh.triangles[id as usize];
                let [a, b, c] = t.map(|v| self.vertex(v));
                self.draw_triangle(frame, id, &a, &b, &c);
            }
            return range.len();
        }
        self.chunks_to_draw(cell, None)
            .map(|k| self.draw_chunk(frame, k))
            .sum()
    }

    /// Draws the chunks of a cell that may cover a pixel centre in `rect` (see
    /// [`View::box_may_show`]): the image is the same as [`Self::draw_cell`]'s wherever the
    /// cell can only show within `rect`. Returns the triangles drawn.
    pub fn draw_cell_within(&self, frame: &mut Rows, cell: u32, rect: &ScreenRect) -> usize {
        if !self.mesh.is_indexed() {
            return self.draw_cell(frame, cell);
        }
        self.chunks_to_draw(cell, Some(std::slice::from_ref(rect)))
            .map(|k| self.draw_chunk(frame, k))
            .sum()
    }

    /// Draws chunk `k`, each vertex transformed once (a vertex is shared by about six
    /// triangles).
    fn draw_chunk(&self, frame: &mut Rows, k: usize) -> usize {
        let mesh = self.mesh;
        let mut buf = self.scratch.borrow_mut();
        buf.clear();
        let vr = mesh.chunk_vertex_ranges[k].clone();
        buf.extend(
            mesh.chunk_vertices[vr.start as usize..vr.end as usize]
                .iter()
                .map(|&v| self.vertex(v)),
        );
        let range = mesh.chunks[k].triangles.clone();
        let local = &mesh.local_triangles[range.start as usize..range.end as usize];
        for (id, t) in (range.start..).zip(local) {
            self.draw_triangle(
                frame,
                id,
                &buf[t[0] as usize],
                &buf[t[1] as usize],
                &buf[t[2] as usize],
            );
        }
        range.len()
    }

    pub fn draw_cells(&self, frame: &mut Rows, cells: &[u32]) -> usize {
        cells.iter().map(|&c| self.draw_cell(frame, c)).sum()
    }

    #[inline]
    fn vertex(&self, v: u32) -> Vertex {
        let xf = &self.xf;
        let rel = Vec3::from_array(self.mesh.positions[v as usize]) - xf.eye;
        let eye = DVec3::new(
            rel.dot(xf.right) as f64,
            rel.dot(xf.up) as f64,
            rel.dot(xf.forward) as f64,
        );
        let normal = Vec3::from_array(self.mesh.normals[v as usize]);
        let screen = if eye.z >= self.view.near {
            self.screen(eye)
        } else {
            ScreenVertex {
                x: 0.0,
                y: 0.0,
                w: 0.0,
            }
        };
        Vertex {
            rel,
            eye,
            normal,
            color: std::cell::Cell::new(Vec3::NAN),
            screen,
        }
    }

    /// The vertex lit (Gouraud), like the GPU's vertex stage: the light sits at the eye.
    #[inline]
    fn color(&self, v: &Vertex) -> Vec3 {
        let Some(shading) = self.shading else {
            return Vec3::ZERO;
        };
        let c = v.color.get();
        if !c.x.is_nan() {
            return c;
        }
        let d2 = v.rel.length_squared();
        let ndl = if d2 > 0.0 {
            -v.normal.dot(v.rel) / d2.sqrt()
        } else {
            0.0
        };
        let l = &shading.lighting;
        let att = 1.0 / (1.0 + d2 / (l.falloff_mm * l.falloff_mm));
        let c = shading.tables.encoded(l, att, ndl);
        v.color.set(c);
        c
    }

    fn draw_triangle(&self, frame: &mut Rows, id: u32, a: &Vertex, b: &Vertex, c: &Vertex) {
        // Back face (or edge-on): its normal does not point toward the eye.
        if (b.rel - a.rel).cross(c.rel - a.rel).dot(a.rel) >= 0.0 {
            return;
        }
        let near = self.view.near;
        let inside = [a, b, c].map(|v| v.eye.z >= near);
        if !inside.iter().any(|&i| i) {
            return;
        }
        if inside.iter().all(|&i| i) {
            self.fill(frame, id, [a.screen, b.screen, c.screen], || {
                [self.color(a), self.color(b), self.color(c)]
            });
            return;
        }
        let v = [a, b, c];
        // Clip against the near plane (Sutherland–Hodgman, one plane): 3 or 4 vertices; the
        // colour is cut in the same proportion as the position (linear in eye space).
        let mut poly: [(DVec3, Vec3); 4] = [(DVec3::ZERO, Vec3::ZERO); 4];
        let mut n = 0;
        for i in 0..3 {
            let (p, q) = (v[i], v[(i + 1) % 3]);
            if p.eye.z >= near {
                poly[n] = (p.eye, self.color(p));
                n += 1;
            }
            if (p.eye.z >= near) != (q.eye.z >= near) {
                let t = (near - p.eye.z) / (q.eye.z - p.eye.z);
                let mut x = p.eye + (q.eye - p.eye) * t;
                x.z = near;
                poly[n] = (
                    x,
                    self.color(p) + (self.color(q) - self.color(p)) * t as f32,
                );
                n += 1;
            }
        }
        let s0 = self.screen(poly[0].0);
        for k in 1..n - 1 {
            self.fill(
                frame,
                id,
                [s0, self.screen(poly[k].0), self.screen(poly[k + 1].0)],
                || [poly[0].1, poly[k].1, poly[k + 1].1],
            );
        }
    }

    #[inline]
    fn screen(&self, e: DVec3) -> ScreenVertex {
        let (x, y) = self.view.project(e);
        ScreenVertex { x, y, w: 1.0 / e.z }
    }

    /// Scan-converts one triangle: pixel centres inside it (top-left rule on edges) take its
    /// id where it is nearer, or as near with a smaller id.
    /// `colors` gives the vertices' colours; it is called only once a pixel centre is known
    /// to lie in the bounding box.
    fn fill(
        &self,
        frame: &mut Rows,
        id: u32,
        [v0, v1, v2]: [ScreenVertex; 3],
        colors: impl FnOnce() -> [Vec3; 3],
    ) {
        let w = frame.width as i64;
        let min_x = v0.x.min(v1.x).min(v2.x);
        let max_x = v0.x.max(v1.x).max(v2.x);
        let min_y = v0.y.min(v1.y).min(v2.y);
        let max_y = v0.y.max(v1.y).max(v2.y);
        // Pixel centres (i + 0.5) inside the bounding box.
        let x0 = ceil_clamped(min_x - 0.5, 0, w - 1);
        let x1 = floor_clamped(max_x - 0.5, 0, w - 1);
        let y0 = ceil_clamped(min_y - 0.5, frame.first, frame.last);
        let y1 = floor_clamped(max_y - 0.5, frame.first, frame.last);
        if x0 > x1 || y0 > y1 || max_x < 0.0 || max_y < frame.first as f64 {
            return;
        }
        let area = (v1.x - v0.x) * (v2.y - v0.y) - (v1.y - v0.y) * (v2.x - v0.x);
        if area == 0.0 || !area.is_finite() {
            return;
        }
        // Edge i is opposite vertex i; its function is positive inside for either winding.
        let e0 = Edge::new(v1, v2, area);
        let e1 = Edge::new(v2, v0, area);
        let e2 = Edge::new(v0, v1, area);
        let inv_area = 1.0 / area.abs();
        let shaded = self.shading.is_some();
        let [c0, c1, c2] = if shaded { colors() } else { [Vec3::ZERO; 3] };
        for py in y0..=y1 {
            let cy = py as f64 + 0.5;
            let (r0, r1, r2) = (e0.row(cy), e1.row(cy), e2.row(cy));
            // Where on this row all three edge functions can be ≥ 0, widened by a pixel so
            // rounding of the division never loses a centre: only those are tested exactly.
            let (mut lo, mut hi) = (x0 as f64 + 0.5, x1 as f64 + 0.5);
            for (e, r) in [(&e0, r0), (&e1, r1), (&e2, r2)]
                .into_iter()
                .filter(|_| x1 - x0 >= SPAN_MIN_WIDTH)
            {
                let a = e.a;
                if a != 0.0 {
                    let x = -r / a;
                    if a > 0.0 {
                        lo = lo.max(x - 1.0)
                    } else {
                        hi = hi.min(x + 1.0)
                    }
                } else if r < 0.0 {
                    hi = f64::NEG_INFINITY;
                }
            }
            if lo.is_nan() || hi.is_nan() || lo > hi {
                continue;
            }
            let sx0 = floor_clamped(lo - 0.5, x0, x1).max(x0);
            let sx1 = ceil_clamped(hi - 0.5, x0, x1).min(x1);
            for px in sx0..=sx1 {
                let cx = px as f64 + 0.5;
                let (d0, d1, d2) = (e0.at(r0, cx), e1.at(r1, cx), e2.at(r2, cx));
                if !(e0.covers(d0) && e1.covers(d1) && e2.covers(d2)) {
                    continue;
                }
                let (p0, p1, p2) = (d0 * v0.w, d1 * v1.w, d2 * v2.w);
                let sum = p0 + p1 + p2;
                let wz = (sum * inv_area) as f32;
                let px = frame.pixel_mut(px, py);
                if wz > px.inv_depth || (wz == px.inv_depth && id < px.id) {
                    let rgb = if shaded {
                        let inv = 1.0 / sum;
                        let c = c0 + (c1 - c0) * (p1 * inv) as f32 + (c2 - c0) * (p2 * inv) as f32;
                        (c * 255.0 + 0.5).to_array().map(|v| v as u8)
                    } else {
                        [0; 3]
                    };
                    *px = Pixel {
                        inv_depth: wz,
                        id,
                        rgb,
                    };
                }
            }
        }
    }
}

/// ⌊x⌋ clamped to [lo, hi] (hi + 1 when x is beyond, so that an empty range stays empty),
/// without a libm call (x86-64's baseline has no rounding instruction).
#[inline]
fn floor_clamped(x: f64, lo: i64, hi: i64) -> i64 {
    if x.is_nan() {
        return lo - 1;
    }
    if x >= hi as f64 + 1.0 {
        return hi;
    }
    if x < lo as f64 {
        return lo - 1;
    }
    let t = x as i64;
    if (t as f64) > x { t - 1 } else { t }
}

/// ⌈x⌉ clamped like [`floor_clamped`]: below lo gives lo, beyond hi gives hi + 1.
#[inline]
fn ceil_clamped(x: f64, lo: i64, hi: i64) -> i64 {
    if x.is_nan() {
        return hi + 1;
    }
    if x <= lo as f64 - 1.0 {
        return lo;
    }
    if x > hi as f64 {
        return hi + 1;
    }
    let t = x as i64;
    if (t as f64) < x { t + 1 } else { t }
}

/// An edge function a·x + b·y + c, evaluated from the edge's endpoints in a canonical order
/// so that the two triangles sharing an edge compute bit-identical values of opposite sign.
#[derive(Clone, Copy)]
struct Edge {
    /// Coefficients already multiplied by the sign (−1 when the canonical order runs against
    /// this triangle's): negation is exact, so the two triangles still agree bit for bit.
    a: f64,
    b: f64,
    c: f64,
    /// Whether a pixel centre exactly on the edge belongs to this triangle (top-left rule).
    owns_ties: bool,
}

impl Edge {
    fn new(p: ScreenVertex, q: ScreenVertex, area: f64) -> Self {
        let flip = (q.x, q.y) < (p.x, p.y);
        let (s, t) = if flip { (q, p) } else { (p, q) };
        let a = -(t.y - s.y);
        let b = t.x - s.x;
        let c = -(a * s.x + b * s.y);
        // Positive inside: for area > 0 the inside lies left of p→q in this formula.
        let sign = if flip { -1.0 } else { 1.0 } * area.signum();
        // The triangle whose signed value grows with +y (or +x on a horizontal edge) owns
        // the ties: exactly one of the two triangles across an edge does.
        let (a, b, c) = (a * sign, b * sign, c * sign);
        let owns_ties = b > 0.0 || (b == 0.0 && a > 0.0);
        Edge { a, b, c, owns_ties }
    }

    #[inline]
    fn row(&self, y: f64) -> f64 {
        self.b * y + self.c
    }

    #[inline]
    fn at(&self, row: f64, x: f64) -> f64 {
        self.a * x + row
    }

    #[inline]
    fn covers(&self, d: f64) -> bool {
        d > 0.0 || (d == 0.0 && self.owns_ties)
    }
}

/// The drawn frame as an image: RGBA8, row-major, top row first; black where empty.
pub fn shade(frame: &Frame) -> Vec<u8> {
    let mut out = vec![0u8; frame.pixels.len() * 4];
    for (px, p) in out.chunks_exact_mut(4).zip(&frame.pixels) {
        px[..3].copy_from_slice(&p.rgb);
        px[3] = 255;
    }
    out
}

/// The lighting the CPU rasterizer shades with, and its tables: whoever draws frames makes
/// one and keeps it (building the tables costs about as much as lighting a small frame).
pub struct Shading {
    lighting: Lighting,
    tables: ShadeTables,
}

impl Shading {
    pub fn new(lighting: &Lighting) -> Self {
        Shading {
            lighting: *lighting,
            tables: ShadeTables::new(lighting),
        }
    }

    pub fn lighting(&self) -> &Lighting {
        &self.lighting
    }
}

impl Default for Shading {
    /// The default [`Lighting`].
    fn default() -> Self {
        Shading::new(&Lighting::default())
    }
}

/// Tables for the two powers per vertex (specular and display gamma), which would otherwise
/// cost more than the rest of the lighting; both agree with the exact formula that the GPU
/// evaluates to far below one 8-bit level.
struct ShadeTables {
    specular: Vec<f32>,
    gamma: Vec<f32>,
}

const SPEC_STEPS: usize = 4096;
const GAMMA_STEPS: usize = 16384;

impl ShadeTables {
    fn new(l: &Lighting) -> Self {
        let specular = (0..=SPEC_STEPS)
            .map(|i| (i as f32 / SPEC_STEPS as f32).powf(l.shininess))
            .collect();
        let gamma = (0..=GAMMA_STEPS)
            .map(|i| (i as f32 / GAMMA_STEPS as f32).powf(1.0 / 2.2))
            .collect();
        ShadeTables { specular, gamma }
    }

    /// Display values (0..1, gamma applied) of [`Lighting::linear`]; the gamma table is
    /// interpolated.
    #[inline]
    fn encoded(&self, l: &Lighting, att: f32, n_dot_l: f32) -> Vec3 {
        let ndl = n_dot_l.clamp(0.0, 1.0);
        let diffuse = l.ambient + (1.0 - l.ambient) * ndl * att;
        let f = ndl * SPEC_STEPS as f32;
        let k = (f as usize).min(SPEC_STEPS - 1);
        let pw = self.specular[k] + (self.specular[k + 1] - self.specular[k]) * (f - k as f32);
        let spec = l.specular * pw * att;
        Vec3::from_array(l.albedo.map(|a| {
            let g = (a * diffuse + spec).clamp(0.0, 1.0) * GAMMA_STEPS as f32;
            let k = (g as usize).min(GAMMA_STEPS - 1);
            self.gamma[k] + (self.gamma[k + 1] - self.gamma[k]) * (g - k as f32)
        }))
    }
}

/// Renders the listed cells and shades them: the CPU path end to end.
pub fn render_rgba(
    mesh: &CellMesh,
    camera: &Camera,
    cells: &[u32],
    width: u32,
    height: u32,
    lighting: &Lighting,
) -> Vec<u8> {
    let view = View::new(camera, width, height);
    let mut frame = Frame::new(width, height);
    Rasterizer::new(mesh, view, &Shading::new(lighting)).draw_cells(&mut frame.rows(), cells);
    shade(&frame)
}

#[cfg(test)]
mod tests {
    use super::*;
    use voyage_nav::Pose;

    /// A square wall 10 mm in front of the camera, facing it, in two triangles; and one
    /// triangle behind it facing away.
    fn wall() -> CellMesh {
        CellMesh {
            positions: vec![
                [-5.0, -5.0, 10.0],
                [5.0, -5.0, 10.0],
                [5.0, 5.0, 10.0],
                [-5.0, 5.0, 10.0],
            ],
            normals: vec![[0.0, 0.0, -1.0]; 4],
            // (b − a) × (c − a) must point toward the camera (−z).
            triangles: vec![[0, 2, 1], [0, 3, 2], [0, 1, 2]],
            cell_ranges: vec![0..2, 2..3],
            surface_triangle: vec![0, 1, 2],
            ..CellMesh::default()
        }
    }

    fn camera() -> Camera {
        Camera::new(Pose::looking(DVec3::ZERO, DVec3::Z, DVec3::Y))
    }

    #[test]
    fn a_facing_square_fills_its_projection_without_gaps_or_overlaps() {
        let mesh = wall();
        let mut f = Frame::new(64, 64);
        let view = View::new(&camera(), 64, 64);
        Rasterizer::new(&mesh, view, &Shading::default()).draw_cells(&mut f.rows(), &[0, 1]);
        // 90° fov: the 10 mm half-width at 10 mm covers half the half-screen → 32 pixels.
        assert_eq!(f.covered(), 32 * 32);
        // The back-facing triangle (id 2) is never drawn.
        assert!(!f.ids().any(|i| i == 2));
        // Depth is 10 mm everywhere on the wall.
        for &Pixel {
            inv_depth: w, id, ..
        } in &f.pixels
        {
            if id != NO_TRIANGLE {
                assert!((w - 0.1).abs() < 1e-6);
            }
        }
        // Drawing in the other order gives the same buffers, and so does the per-cell vertex
        // path.
        let mut g = Frame::new(64, 64);
        Rasterizer::new(&mesh, view, &Shading::default()).draw_cells(&mut g.rows(), &[1, 0]);
        assert_eq!(f, g);
        let mut indexed = mesh.clone();
        indexed.index_cells();
        assert!(indexed.is_indexed() && !mesh.is_indexed());
        let mut h = Frame::new(64, 64);
        Rasterizer::new(&indexed, view, &Shading::default()).draw_cells(&mut h.rows(), &[1, 0]);
        assert_eq!(f, h);
        // Drawn band by band, each band on its own, the same buffers: the wall (rows 16–47)
        // crosses the bands' borders at rows 21 and 42.
        let mut b = Frame::new(64, 64);
        let bands = b.bands(3);
        let heights: Vec<i64> = bands.iter().map(|r| r.last() - r.first() + 1).collect();
        assert_eq!(heights, [21, 21, 22]);
        for mut rows in bands {
            Rasterizer::new(&indexed, view, &Shading::default()).draw_cells(&mut rows, &[0, 1]);
        }
        assert_eq!(f, b);
    }

    #[test]
    fn a_box_may_show_only_where_its_projection_meets_the_rect() {
        // Looking along +z from the origin, 90° field of view, 100×100 pixels.
        let view = View::new(&camera(), 100, 100);
        let all = ScreenRect::full(&view);
        let left = ScreenRect {
            x0: 0,
            x1: 20,
            y0: 0,
            y1: 99,
        };
        // In front, in the middle of the view.
        let mid = ([-1.0, -1.0, 10.0], [1.0, 1.0, 11.0]);
        assert!(view.box_may_show(mid.0, mid.1, &all));
        assert!(!view.box_may_show(mid.0, mid.1, &left));
        // Behind the eye, and beside the view.
        assert!(!view.box_may_show([-1.0, -1.0, -5.0], [1.0, 1.0, -4.0], &all));
        assert!(!view.box_may_show([30.0, -1.0, 10.0], [31.0, 1.0, 11.0], &all));
        // Across the near plane: kept, its projection is unbounded.
        assert!(view.box_may_show([5.0, 5.0, -1.0], [6.0, 6.0, 1.0], &left));
        // An empty rect shows nothing.
        let empty = ScreenRect {
            x0: 1,
            x1: 0,
            ..all
        };
        assert!(!view.box_may_show(mid.0, mid.1, &empty));
    }

    #[test]
    fn floor_and_ceil_match_the_library() {
        for &x in &[
            -3.5, -1.0, -0.5, -0.0, 0.0, 0.25, 0.5, 1.0, 2.999, 3.0, 3.5, 9.0, 1e12, -1e12,
        ] {
            assert_eq!(
                floor_clamped(x, 0, 5),
                (x.floor() as i64).clamp(-1, 5),
                "{x}"
            );
            assert_eq!(ceil_clamped(x, 0, 5), (x.ceil() as i64).clamp(0, 6), "{x}");
        }
        assert_eq!(floor_clamped(f64::NAN, 0, 5), -1);
        assert_eq!(ceil_clamped(f64::NAN, 0, 5), 6);
    }

    #[test]
    fn near_clipping_keeps_the_part_in_front() {
        // A floor running from behind the camera to far ahead: half the screen below the
        // horizon is floor.
        let mesh = CellMesh {
            positions: vec![
                [-100.0, -2.0, -50.0],
                [100.0, -2.0, -50.0],
                [100.0, -2.0, 500.0],
                [-100.0, -2.0, 500.0],
            ],
            normals: vec![[0.0, 1.0, 0.0]; 4],
            triangles: vec![[0, 2, 1], [0, 3, 2]],
            cell_ranges: std::iter::once(0..2).collect(),
            surface_triangle: vec![0, 1],
            ..CellMesh::default()
        };
        let mut f = Frame::new(32, 32);
        Rasterizer::new(&mesh, View::new(&camera(), 32, 32), &Shading::default())
            .draw_cells(&mut f.rows(), &[0]);
        let below = (16..32)
            .flat_map(|y| (0..32).map(move |x| (x, y)))
            .filter(|&(x, y)| f.id(y * 32 + x) != NO_TRIANGLE)
            .count();
        let above = (0..16)
            .flat_map(|y| (0..32).map(move |x| (x, y)))
            .filter(|&(x, y)| f.id(y * 32 + x) != NO_TRIANGLE)
            .count();
        assert_eq!(above, 0);
        // The floor ends 500 mm ahead: rows just below the horizon see past its end.
        assert!(below > 14 * 32, "{below}");
    }

    #[test]
    fn shading_is_brightest_facing_the_light() {
        // A wall 10 mm ahead in a fine grid, so that lighting at the vertices and interpolated
        // between them is close to lighting every pixel.
        let (n, half) = (40usize, 5.0f32);
        let mut mesh = CellMesh::default();
        for j in 0..=n {
            for i in 0..=n {
                let x = -half + 2.0 * half * i as f32 / n as f32;
                let y = -half + 2.0 * half * j as f32 / n as f32;
                mesh.positions.push([x, y, 10.0]);
                mesh.normals.push([0.0, 0.0, -1.0]);
            }
        }
        let at = |i: usize, j: usize| (j * (n + 1) + i) as u32;
        for j in 0..n {
            for i in 0..n {
                mesh.triangles
                    .push([at(i, j), at(i + 1, j + 1), at(i + 1, j)]);
                mesh.triangles
                    .push([at(i, j), at(i, j + 1), at(i + 1, j + 1)]);
            }
        }
        mesh.cell_ranges = std::iter::once(0..mesh.triangles.len() as u32).collect();
        mesh.index_cells();
        let rgba = render_rgba(&mesh, &camera(), &[0], 64, 64, &Lighting::default());
        let px = |x: usize, y: usize| rgba[(y * 64 + x) * 4];
        // Centre (facing, nearest) brighter than the corner of the wall; background black.
        assert!(px(32, 32) > px(17, 17));
        assert_eq!(px(2, 2), 0);
        let want = Lighting::default().rgb8(
            10.0 * (1.0 + 2.0 * (0.5f64 / 32.0).powi(2)).sqrt() as f32,
            1.0,
        );
        assert!(
            (px(32, 32) as i32 - want[0] as i32).abs() <= 1,
            "{} vs {}",
            px(32, 32),
            want[0]
        );
    }
}
