//! The scout panel (paper §5): the whole colon from outside, semi-transparent, with the
//! centerline, the markers and the submarine; orbit and zoom; a click on the centerline
//! moves the submarine there.
//!
//! The surface drawn here is the study's mesh decimated by vertex clustering (a few mm):
//! the scout shows shape, not mucosa, and tens of thousands of triangles blend fast on any
//! renderer, where the full mesh (over a million) would not. It is alpha-blended on the
//! CPU over the panel's colour into an opaque image (redrawn when the view changes) that is
//! shown pixel for pixel ([`PanelImage`]), so it needs no depth buffer and costs little per
//! frame while the submarine flies.

use std::collections::HashMap;

use egui::{Color32, Pos2, Rect, Sense, Shape, Stroke, Vec2};
use glam::{DMat3, DVec3};
use voyage_core::{Geometry, Mesh};

use super::pixels::{PanelImage, Rgba};

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
}

/// What the scout shows besides the colon.
pub struct ScoutMarks<'a> {
    pub centerline: &'a [[f64; 3]],
    /// The centerline points' distance from the rectum end (mm).
    pub arc_mm: &'a [f64],
    /// (label, position).
    pub markers: Vec<(String, DVec3)>,
    pub submarine: DVec3,
    pub view_dir: DVec3,
    /// Per scout vertex, the share of its mucosa not yet seen, and a number that changes
    /// whenever the shares do (None: no colouring).
    pub unseen: Option<(&'a [f32], u64)>,
}

/// How near the pointer must come to the centerline on the scout to pick it (points): a
/// generous target, as the line is thin and the colon small on a full-size scout.
pub const PICK_POINTS: f32 = 16.0;

/// What a click on the scout did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ScoutClick {
    /// Picked centerline point i.
    Centerline(usize),
    /// Missed: the centerline was this far from the click (points).
    Missed(f32),
}

/// The scout's orbit camera and its cached mesh.
pub struct ScoutView {
    /// Where the centerline's middle point and the point 5 on were drawn in the last frame
    /// (points), for tools that click the line from outside (tests with xdotool).
    pub probe: Option<[Pos2; 2]>,
    /// The centerline point under the pointer in the last frame, if any.
    pub hovered: Option<usize>,
    yaw: f64,
    pitch: f64,
    zoom: f64,
    /// Patient axes in the volume's local frame: left, posterior, superior.
    anatomy: DMat3,
    /// The view the image was drawn for, and where the image's top-left pixel lies in the
    /// panel (pixels): it holds only the part the colon covers.
    cached: Option<(CacheKey, [usize; 2])>,
    image: PanelImage,
    /// The window's colour behind the scout.
    background: Color32,
}

#[derive(Clone, Copy, PartialEq)]
struct CacheKey {
    yaw: f64,
    pitch: f64,
    zoom: f64,
    rect: Rect,
    unseen: Option<u64>,
}

/// An orthographic view: screen right, screen up and the viewing direction in local mm.
struct Projection {
    right: DVec3,
    up: DVec3,
    forward: DVec3,
    center: DVec3,
    scale: f64,
    origin: Pos2,
}

impl Projection {
    fn to_screen(&self, p: DVec3) -> Pos2 {
        let d = p - self.center;
        Pos2::new(
            self.origin.x + (d.dot(self.right) * self.scale) as f32,
            self.origin.y - (d.dot(self.up) * self.scale) as f32,
        )
    }
}

impl ScoutView {
    /// `image_key`: the scout's slot among the window's pixel images; `gpu`: the window's
    /// renderer holds them.
    pub fn new(geometry: &Geometry, background: Color32, image_key: u64, gpu: bool) -> Self {
        // local = Dᵀ (patient − origin): a patient axis e is Dᵀ e in the local frame.
        let d = geometry.direction_mat().transpose();
        ScoutView {
            probe: None,
            hovered: None,
            yaw: 0.0,
            pitch: 0.0,
            zoom: 1.0,
            anatomy: d,
            cached: None,
            image: PanelImage::new(image_key, "scout", gpu),
            background,
        }
    }

    /// Front view (from the patient's anterior, the patient's right on the screen's left,
    /// head up), the radiologist's usual first look at a colon.
    fn projection(&self, mesh: &ScoutMesh, rect: Rect) -> Projection {
        let (l, p, s) = (
            self.anatomy.x_axis,
            self.anatomy.y_axis,
            self.anatomy.z_axis,
        );
        // Orbit: yaw about the body's long axis, then pitch about the screen's right.
        let yaw = DMat3::from_axis_angle(s, self.yaw);
        let (right0, forward0) = (yaw * l, yaw * p);
        let pitch = DMat3::from_axis_angle(right0, self.pitch);
        let (forward, up) = (pitch * forward0, pitch * s);
        let scale = 0.5 * rect.width().min(rect.height()) as f64 / mesh.radius * self.zoom;
        Projection {
            right: right0,
            up,
            forward,
            center: mesh.center,
            scale,
            origin: rect.center(),
        }
    }

    /// Draws the scout into `ui`'s remaining space, the centerline under the pointer
    /// highlighted; returns what a click did: the centerline point picked (within
    /// [`PICK_POINTS`] of the line), or a miss.
    pub fn show(
        &mut self,
        ui: &mut egui::Ui,
        mesh: &ScoutMesh,
        marks: &ScoutMarks,
    ) -> Option<ScoutClick> {
        let (rect, response) = ui.allocate_exact_size(ui.available_size(), Sense::click_and_drag());
        if response.dragged_by(egui::PointerButton::Primary)
            || response.dragged_by(egui::PointerButton::Secondary)
        {
            let d = response.drag_delta();
            self.yaw += d.x as f64 * 0.01;
            self.pitch = (self.pitch + d.y as f64 * 0.01).clamp(-1.55, 1.55);
        }
        if response.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y);
            if scroll != 0.0 {
                self.zoom = (self.zoom * (1.0 + scroll as f64 * 0.002)).clamp(0.3, 12.0);
            }
        }
        if response.double_clicked() {
            (self.yaw, self.pitch, self.zoom) = (0.0, 0.0, 1.0);
        }
        let painter = ui.painter_at(rect);
        let proj = self.projection(mesh, rect);
        let ppp = ui.ctx().pixels_per_point();
        // Only the part the colon covers: the rest shows the window's colour anyway, and on a
        // CPU Vulkan driver every pixel drawn costs.
        let offset = self.surface(mesh, marks, &proj, rect, ppp);
        let at = ((rect.min.to_vec2() * ppp).round()
            + Vec2::new(offset[0] as f32, offset[1] as f32))
            / ppp;
        self.image.paint(&painter, at.to_pos2());

        let line: Vec<Pos2> = marks
            .centerline
            .iter()
            .map(|p| proj.to_screen(DVec3::from_array(*p)))
            .collect();
        for (label, p) in &marks.markers {
            let s = proj.to_screen(*p);
            painter.circle_filled(s, 4.0, Color32::YELLOW);
            painter.text(
                s + Vec2::new(6.0, -6.0),
                egui::Align2::LEFT_BOTTOM,
                label,
                egui::FontId::proportional(12.0),
                Color32::YELLOW,
            );
        }
        draw_submarine(&painter, &proj, marks.submarine, marks.view_dir);
        painter.text(
            rect.left_top() + Vec2::new(6.0, 4.0),
            egui::Align2::LEFT_TOP,
            "scout · drag: orbit · scroll: zoom · click centerline: go",
            egui::FontId::proportional(11.0),
            Color32::from_gray(150),
        );

        let mid = line.len() / 2;
        self.probe = line.get(mid + 5).map(|&on| [line[mid], on]);
        let near = |p: Pos2| nearest_on_line(&line, p);
        self.hovered = response
            .hover_pos()
            .and_then(near)
            .filter(|&(_, d)| d <= PICK_POINTS)
            .map(|(i, _)| i);
        if let Some(i) = self.hovered {
            highlight(&painter, &line, i, marks.arc_mm);
        }
        if response.clicked() {
            let at = response.interact_pointer_pos()?;
            return near(at).map(|(i, d)| {
                if d <= PICK_POINTS {
                    ScoutClick::Centerline(i)
                } else {
                    ScoutClick::Missed(d)
                }
            });
        }
        None
    }

    /// The colon changed (a correction): the image is drawn again, from the same orbit.
    pub fn colon_changed(&mut self) {
        self.cached = None;
    }

    /// The decimated surface, drawn on the CPU into an image that is redrawn only when the
    /// view changes: the scout stands still while the submarine flies, and a CPU Vulkan
    /// driver would otherwise blend every scout triangle again each frame. Faces seen
    /// edge-on are more opaque than faces seen head-on: the outline and the folds stand out
    /// while the far side shows through (an "x-ray" look). Returns where the image's
    /// top-left pixel lies in the panel.
    fn surface(
        &mut self,
        mesh: &ScoutMesh,
        marks: &ScoutMarks,
        proj: &Projection,
        rect: Rect,
        ppp: f32,
    ) -> [usize; 2] {
        let key = CacheKey {
            yaw: self.yaw,
            pitch: self.pitch,
            zoom: self.zoom,
            rect,
            unseen: marks.unseen.map(|(_, version)| version),
        };
        if let Some((k, offset)) = &self.cached
            && *k == key
        {
            return *offset;
        }
        let (w, h) = (
            ((rect.width() * ppp).round() as usize).max(1),
            ((rect.height() * ppp).round() as usize).max(1),
        );
        let unseen = marks.unseen.map(|(shares, _)| shares);
        let buf = rasterize(mesh, marks.centerline, unseen, proj, rect, ppp, [w, h]);
        let (offset, image) = over_background(&buf, [w, h], self.background);
        self.image.set(image);
        self.cached = Some((key, offset));
        offset
    }
}

/// The centerline point nearest `p` on the screen polyline `line`, and the distance from `p`
/// to the line (points): segments, not only points, so a click between two far-apart
/// points of a zoomed scout still picks.
fn nearest_on_line(line: &[Pos2], p: Pos2) -> Option<(usize, f32)> {
    if line.len() == 1 {
        return Some((0, line[0].distance(p)));
    }
    line.windows(2)
        .enumerate()
        .map(|(i, w)| {
            let (a, b) = (w[0], w[1]);
            let ab = b - a;
            let t = ((p - a).dot(ab) / ab.length_sq().max(f32::MIN_POSITIVE)).clamp(0.0, 1.0);
            let d = (a + ab * t).distance(p);
            (if t < 0.5 { i } else { i + 1 }, d)
        })
        .min_by(|x, y| x.1.total_cmp(&y.1))
}

/// The centerline's stretch around point `i` drawn bright, with a ring at `i` and its
/// distance from the rectum: what a click there will do.
fn highlight(painter: &egui::Painter, line: &[Pos2], i: usize, arc_mm: &[f64]) {
    let hot = Color32::from_rgb(255, 230, 60);
    let span = &line[i.saturating_sub(15)..(i + 16).min(line.len())];
    painter.add(Shape::line(span.to_vec(), Stroke::new(3.0, hot)));
    painter.circle_stroke(line[i], 6.0, Stroke::new(2.0, hot));
    if let Some(arc) = arc_mm.get(i) {
        // On the side of the panel with room for it.
        let (offset, align) = if line[i].x > painter.clip_rect().center().x {
            (Vec2::new(-9.0, -9.0), egui::Align2::RIGHT_BOTTOM)
        } else {
            (Vec2::new(9.0, -9.0), egui::Align2::LEFT_BOTTOM)
        };
        painter.text(
            line[i] + offset,
            align,
            format!("go to {arc:.0} mm"),
            egui::FontId::proportional(12.0),
            hot,
        );
    }
}

/// The premultiplied image `buf` of `size` over an opaque `background`, cropped to the
/// pixels that are not fully transparent: (the crop's top-left pixel, the crop). An image
/// with nothing in it gives a 0 × 0 crop.
fn over_background(buf: &[[f32; 4]], size: [usize; 2], background: Color32) -> ([usize; 2], Rgba) {
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
    let bg = [background.r(), background.g(), background.b()].map(|c| c as f32 / 255.0);
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

/// Alpha-blends the scout's triangles, in the mesh's order, into an image of `rect` at
/// `ppp` pixels per point, `size` pixels (premultiplied colour, transparent where nothing
/// is), and draws the centerline over them in green (the paper's colour). With `unseen`
/// shares per vertex, mucosa not yet seen is blue, and more opaque, so that it shows
/// through the rest.
fn rasterize(
    mesh: &ScoutMesh,
    centerline: &[[f64; 3]],
    unseen: Option<&[f32]>,
    proj: &Projection,
    rect: Rect,
    ppp: f32,
    size: [usize; 2],
) -> Vec<[f32; 4]> {
    let [w, h] = size;
    let mut buf = vec![[0f32; 4]; w * h];
    let to_px = |p: DVec3| {
        let s = proj.to_screen(p);
        [
            ((s.x - rect.left()) * ppp) as f64,
            ((s.y - rect.top()) * ppp) as f64,
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

/// The submarine: a dot where it is and an arrow along its view direction.
fn draw_submarine(painter: &egui::Painter, proj: &Projection, at: DVec3, dir: DVec3) {
    let s = proj.to_screen(at);
    let screen_dir = Vec2::new(dir.dot(proj.right) as f32, -dir.dot(proj.up) as f32);
    let len = screen_dir.length();
    let tip = if len > 1e-3 {
        s + screen_dir / len * (18.0 * len.max(0.35))
    } else {
        s
    };
    let color = Color32::from_rgb(60, 200, 255);
    painter.line_segment([s, tip], Stroke::new(2.5, color));
    if len > 1e-3 {
        let d = (tip - s).normalized();
        let n = Vec2::new(-d.y, d.x);
        painter.add(Shape::convex_polygon(
            vec![tip + d * 6.0, tip + n * 4.0, tip - n * 4.0],
            color,
            Stroke::NONE,
        ));
    }
    painter.circle(
        s,
        5.0,
        Color32::from_rgb(20, 60, 90),
        Stroke::new(2.0, color),
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scout_image_is_cropped_and_laid_over_the_background() {
        let bg = Color32::from_gray(20);
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
}
