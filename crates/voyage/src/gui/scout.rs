//! The scout panel (paper §5): the whole colon from outside, semi-transparent, with the
//! centerline, the markers and the submarine; orbit and zoom; a click on the centerline
//! moves the submarine there.
//!
//! Only the widget is here: input, picking on the screen, the highlight, the markers and
//! the submarine drawn over the picture. The picture itself (the study's mesh decimated,
//! alpha-blended on the CPU over the panel's colour) is voyage-view's [`scout_image`]; it
//! is redrawn only when the view changes and shown pixel for pixel ([`PanelImage`]), so it
//! needs no depth buffer and costs little per frame while the submarine flies.

use egui::{Color32, Pos2, Rect, Sense, Shape, Stroke, Vec2};
use glam::{DMat3, DVec3};
use voyage_core::Geometry;
use voyage_view::{ScoutCanvas, ScoutMesh, ScoutOrbit, ScoutProjection, scout_image};

use super::pixels::PanelImage;

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
    orbit: ScoutOrbit,
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
    orbit: ScoutOrbit,
    rect: Rect,
    unseen: Option<u64>,
}

/// Where a local point lies on the scout's panel (points).
fn to_screen(proj: &ScoutProjection, p: DVec3) -> Pos2 {
    let s = proj.to_screen(p);
    Pos2::new(s.x, s.y)
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
            orbit: ScoutOrbit::FRONT,
            anatomy: d,
            cached: None,
            image: PanelImage::new(image_key, "scout", gpu),
            background,
        }
    }

    /// The orbit's view of `mesh` in `rect`; from the front at first (from the patient's
    /// anterior, the patient's right on the screen's left, head up).
    fn projection(&self, mesh: &ScoutMesh, rect: Rect) -> ScoutProjection {
        let centre = rect.center();
        ScoutProjection::new(
            self.anatomy,
            self.orbit,
            mesh,
            glam::Vec2::new(rect.width(), rect.height()),
            glam::Vec2::new(centre.x, centre.y),
        )
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
            let o = &mut self.orbit;
            o.yaw += d.x as f64 * 0.01;
            o.pitch = (o.pitch + d.y as f64 * 0.01).clamp(-1.55, 1.55);
        }
        if response.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y);
            if scroll != 0.0 {
                let o = &mut self.orbit;
                o.zoom = (o.zoom * (1.0 + scroll as f64 * 0.002)).clamp(0.3, 12.0);
            }
        }
        if response.double_clicked() {
            self.orbit = ScoutOrbit::FRONT;
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
            .map(|p| to_screen(&proj, DVec3::from_array(*p)))
            .collect();
        for (label, p) in &marks.markers {
            let s = to_screen(&proj, *p);
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

    /// The decimated surface, drawn on the CPU ([`scout_image`]) into an image that is
    /// redrawn only when the view changes: the scout stands still while the submarine
    /// flies, and a CPU Vulkan driver would otherwise blend every scout triangle again each
    /// frame. Returns where the image's top-left pixel lies in the panel.
    fn surface(
        &mut self,
        mesh: &ScoutMesh,
        marks: &ScoutMarks,
        proj: &ScoutProjection,
        rect: Rect,
        ppp: f32,
    ) -> [usize; 2] {
        let key = CacheKey {
            orbit: self.orbit,
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
        let canvas = ScoutCanvas {
            top_left: glam::Vec2::new(rect.left(), rect.top()),
            ppp,
            size: [w, h],
        };
        let bg = self.background;
        let (offset, image) = scout_image(
            mesh,
            marks.centerline,
            unseen,
            proj,
            canvas,
            [bg.r(), bg.g(), bg.b()],
        );
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

/// The submarine: a dot where it is and an arrow along its view direction.
fn draw_submarine(painter: &egui::Painter, proj: &ScoutProjection, at: DVec3, dir: DVec3) {
    let s = to_screen(proj, at);
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
