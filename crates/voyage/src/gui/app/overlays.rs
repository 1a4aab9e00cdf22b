//! What is drawn over the endoscopic view: the close-up volume rendering and the
//! translucency view in a box around a point, the centerline, the patch visited, markers,
//! measurements and the read-outs.

use egui::{Color32, Pos2, Rect, Stroke, Vec2};
use glam::DVec3;
use voyage_nav::{Camera, Direction};
use voyage_view::{
    CloseupBox, Material, TransferFunction, TranslucencyOptions, encode, render_closeup,
    render_translucency,
};

use super::{App, actions::Tool};
use crate::gui::endoscopy::{label, project, surface_point_on_screen, visible_centerline};

/// An image shown over the view (the close-up volume rendering, the translucency view), and
/// the camera and box centre it was made for.
struct Closeup {
    texture: egui::TextureHandle,
    camera: Camera,
    center: DVec3,
}

/// The close-up volume rendering and the translucency view over the endoscopic view: each on
/// or off with the last image drawn, and the marker whose neighbourhood they show.
#[derive(Default)]
pub(super) struct BoxViews {
    pub(super) closeup_on: bool,
    pub(super) translucency_on: bool,
    closeup: Option<Closeup>,
    translucency: Option<Closeup>,
    /// Marker whose neighbourhood the boxes show (instead of the view centre's surface).
    pub(super) at: Option<DVec3>,
}

impl BoxViews {
    /// The images are of another CT or lumen: drawn again.
    pub(super) fn images_stale(&mut self) {
        (self.closeup, self.translucency) = (None, None);
    }

    /// Another study or position: the images and the marker shown go.
    pub(super) fn reset(&mut self) {
        self.images_stale();
        self.at = None;
    }
}

impl App {
    /// Where a box over the view is drawn from: the camera, and the marker flown back to or
    /// the surface point at the view's centre.
    fn overlay_target(&self, rect: Rect) -> Option<(Camera, DVec3)> {
        let s = self.session.as_ref()?;
        let center = match self.boxes.at {
            Some(c) => c,
            None => self.pick(rect.center())?.point,
        };
        Some((s.camera(), center))
    }

    /// The close-up volume rendering over the view: the CT ray-cast in a small box around
    /// the marker flown back to, or around the surface point at the view's centre.
    pub(super) fn closeup_overlay(&mut self, ui: &egui::Ui, rect: Rect) {
        if !self.boxes.closeup_on {
            self.boxes.closeup = None;
            return;
        }
        let (Some((cam, center)), Some(s)) = (self.overlay_target(rect), &self.session) else {
            return;
        };
        let region = CloseupBox {
            center,
            half_size_mm: 15.0,
        };
        show_overlay(
            &mut self.boxes.closeup,
            ui,
            rect,
            "closeup",
            cam,
            center,
            |w, h| {
                render_closeup(
                    &s.study.ct,
                    &cam,
                    &region,
                    w,
                    h,
                    &TransferFunction::tissue(),
                )
            },
        );
    }

    /// The translucency view over the view: the surface in a box around the marker flown back
    /// to, or around the surface point at the view's centre, coloured by what lies beneath
    /// it, with its legend.
    pub(super) fn translucency_overlay(&mut self, ui: &egui::Ui, rect: Rect) {
        if !self.boxes.translucency_on {
            self.boxes.translucency = None;
            return;
        }
        let (Some((cam, center)), Some(s)) = (self.overlay_target(rect), &self.session) else {
            return;
        };
        let region = CloseupBox {
            center,
            half_size_mm: voyage_view::HALF_SIZE_MM,
        };
        show_overlay(
            &mut self.boxes.translucency,
            ui,
            rect,
            "translucency",
            cam,
            center,
            |w, h| {
                render_translucency(
                    s.surface_ct(),
                    &s.study.segmentation.lumen,
                    &cam,
                    &region,
                    w,
                    h,
                    &TranslucencyOptions::default(),
                )
                .rgba
            },
        );
        translucency_legend(&ui.painter_at(rect), rect);
    }

    /// Centerline, markers, measurements and the read-outs over the view.
    pub(super) fn overlays(&mut self, ui: &egui::Ui, rect: Rect) {
        let Some(s) = &self.session else { return };
        let cam = s.camera();
        let painter = ui.painter_at(rect);
        if self.show_centerline {
            for line in visible_centerline(s, &cam, rect, 250.0) {
                painter.add(egui::Shape::line(
                    line,
                    Stroke::new(2.0, Color32::from_rgb(40, 230, 60)),
                ));
            }
        }
        // The patch visited: the edges of its outline the camera sees, within reading
        // distance (a long patch's far edges would only clutter the view).
        let aspect = (rect.width() / rect.height().max(1.0)) as f64;
        let on_screen = |p: DVec3| project(&cam, p, aspect).map(|f| rect.min + f * rect.size());
        let orange = Stroke::new(2.0, Color32::from_rgb(255, 150, 30));
        let reach = s.coverage.session.options().reading_distance_mm;
        for [a, b] in &s.coverage.outline {
            let mid = 0.5 * (*a + *b);
            if mid.distance(cam.pose.position) > reach
                || surface_point_on_screen(s, &cam, rect, mid).is_none()
            {
                continue;
            }
            if let (Some(a), Some(b)) = (on_screen(*a), on_screen(*b)) {
                painter.line_segment([a, b], orange);
            }
        }
        if let Some((name, x)) = &self.looked_up
            && let Some(p) = surface_point_on_screen(s, &cam, rect, *x)
        {
            let cyan = Color32::from_rgb(80, 220, 255);
            painter.circle_stroke(p, 9.0, Stroke::new(2.0, cyan));
            label(&painter, p + Vec2::new(10.0, 6.0), name, cyan);
        }
        for m in &self.findings.markers {
            if let Some(p) = surface_point_on_screen(s, &cam, rect, m.position) {
                painter.circle(
                    p,
                    6.0,
                    Color32::from_rgba_unmultiplied(255, 230, 0, 90),
                    Stroke::new(2.0, Color32::YELLOW),
                );
                label(
                    &painter,
                    p + Vec2::new(8.0, -20.0),
                    &m.label,
                    Color32::YELLOW,
                );
            }
        }
        if let Some([a, b]) = self.polyp_span
            && let (Some(pa), Some(pb)) = (on_screen(a), on_screen(b))
        {
            let violet = Color32::from_rgb(220, 120, 255);
            painter.line_segment([pa, pb], Stroke::new(2.0, violet));
            label(
                &painter,
                pb + Vec2::new(6.0, -8.0),
                &format!("{:.1} mm", a.distance(b)),
                violet,
            );
        }
        let measure_color = Color32::from_rgb(120, 220, 255);
        for m in &self.findings.measurements {
            let (a, b) = (
                surface_point_on_screen(s, &cam, rect, m.a),
                surface_point_on_screen(s, &cam, rect, m.b),
            );
            if let (Some(a), Some(b)) = (a, b) {
                painter.line_segment([a, b], Stroke::new(2.0, measure_color));
                painter.circle_filled(a, 3.0, measure_color);
                painter.circle_filled(b, 3.0, measure_color);
                label(
                    &painter,
                    a.lerp(b, 0.5) + Vec2::new(6.0, 6.0),
                    &format!("{} {:.1} mm", m.label, m.length_mm()),
                    measure_color,
                );
            }
        }
        if let Some(a) = self.measure_from
            && let Some(p) = surface_point_on_screen(s, &cam, rect, a)
        {
            painter.circle_filled(p, 4.0, measure_color);
        }
        // One figure, one way: the mean frame time over the frames kept, and its inverse.
        let frames = self.times.summary();
        let stats = &self.endoscope.stats;
        let readout = format!(
            "frame {:.1} ms = {:.0} fps (mean of {}) · view {:.1} ms · {} cells, {}k triangles · {}",
            frames.mean,
            frames.fps,
            frames.frames,
            stats.render_ms,
            stats.cells,
            stats.triangles / 1000,
            if self.endoscope.is_gpu() {
                "GPU"
            } else {
                "CPU"
            }
        );
        label(
            &painter,
            rect.left_top() + Vec2::new(8.0, 8.0),
            &readout,
            Color32::from_gray(220),
        );
        let mode = format!(
            "{} · {} · wall {:.1} mm{}{}{}",
            if s.playing {
                "flying"
            } else if s.coverage.reading_running() {
                "reading"
            } else {
                "paused"
            },
            if s.direction() == Direction::Forward {
                "rectum to cecum"
            } else {
                "cecum to rectum"
            },
            s.field.ds(s.sub.state.x),
            if s.sub.modes.compass {
                " · compass"
            } else {
                ""
            },
            if s.sub.modes.leveling {
                " · leveling"
            } else {
                ""
            },
            if s.sub.modes.still { " · still" } else { "" }
        );
        let mode_rect = label(
            &painter,
            rect.left_bottom() + Vec2::new(8.0, -26.0),
            &mode,
            Color32::from_gray(220),
        );
        if let Some(gap) = s.collapsed_here() {
            let text = if gap.at_edge() {
                format!(
                    "the colon leaves the scan here: {:.0} mm joined inside it, the flight keeps to the path",
                    gap.length_mm
                )
            } else if gap.at_catheter {
                format!(
                    "beside the rectal catheter (its balloon, or the canal round it), {:.0} mm joined: the flight keeps to the path",
                    gap.length_mm
                )
            } else if gap.fluid_filled {
                format!(
                    "fluid-filled stretch, {:.0} mm: {}, the flight keeps to the path",
                    gap.length_mm,
                    if s.study.cleansing.is_empty() {
                        "tagged fluid fills it"
                    } else {
                        "its tagged fluid is cleansed away"
                    }
                )
            } else {
                format!(
                    "collapsed segment, {:.0} mm: no air here, the flight keeps to the path",
                    gap.length_mm
                )
            };
            label(
                &painter,
                rect.left_top() + Vec2::new(8.0, 30.0),
                &text,
                Color32::from_rgb(255, 190, 120),
            );
        }
        let tool = match (self.tool, self.measure_from.is_some()) {
            (Tool::Steer, _) => "hold left: steer · right-drag: look · H: help",
            (Tool::Marker, _) => "click: marker on the surface",
            (Tool::Measure, false) => "click: first point of the measurement",
            (Tool::Measure, true) => "click: second point",
            (Tool::Polyp, _) => "click a polyp: its size",
        };
        // Beside the mode where there is room, else a line above it.
        let beside = mode_rect.right() + 8.0 <= rect.right() - 300.0;
        let tool_at = rect.right_bottom() + Vec2::new(-300.0, if beside { -26.0 } else { -48.0 });
        label(&painter, tool_at, tool, Color32::from_gray(200));
        // A small crosshair at the view's centre: where the close-up looks by default.
        let c = rect.center();
        painter.line_segment(
            [c - Vec2::new(6.0, 0.0), c + Vec2::new(6.0, 0.0)],
            Stroke::new(1.0, Color32::from_white_alpha(90)),
        );
        painter.line_segment(
            [c - Vec2::new(0.0, 6.0), c + Vec2::new(0.0, 6.0)],
            Stroke::new(1.0, Color32::from_white_alpha(90)),
        );
    }
}

/// The translucency view's colours, in the view's lower left corner above the status line.
fn translucency_legend(painter: &egui::Painter, rect: Rect) {
    let row = 18.0;
    let top = rect.bottom() - 36.0 - row * Material::ALL.len() as f32;
    painter.rect_filled(
        Rect::from_min_size(
            Pos2::new(rect.left() + 6.0, top - 4.0),
            Vec2::new(210.0, row * Material::ALL.len() as f32 + 8.0),
        ),
        4.0,
        Color32::from_black_alpha(160),
    );
    for (i, m) in Material::ALL.iter().enumerate() {
        let y = top + row * i as f32;
        let [r, g, b] = m.rgb().map(encode);
        painter.rect_filled(
            Rect::from_min_size(Pos2::new(rect.left() + 12.0, y + 3.0), Vec2::splat(12.0)),
            2.0,
            Color32::from_rgb(r, g, b),
        );
        painter.text(
            Pos2::new(rect.left() + 30.0, y + 9.0),
            egui::Align2::LEFT_CENTER,
            m.name(),
            egui::FontId::proportional(13.0),
            Color32::WHITE,
        );
    }
}

/// An image over the whole view made by `render` (width, height → RGBA, straight alpha) for
/// a camera and a box's centre, redrawn only when they change, at half the view's resolution
/// and at most 384 px wide: the box is small on screen and ray casting is the costly part.
fn show_overlay(
    slot: &mut Option<Closeup>,
    ui: &egui::Ui,
    rect: Rect,
    name: &str,
    camera: Camera,
    center: DVec3,
    render: impl FnOnce(u32, u32) -> Vec<u8>,
) {
    if !slot
        .as_ref()
        .is_some_and(|c| c.camera == camera && c.center == center)
    {
        let w = (rect.width() * 0.5).clamp(64.0, 384.0) as u32;
        let h = ((w as f32) * rect.height() / rect.width()).max(16.0) as u32;
        let image =
            egui::ColorImage::from_rgba_unmultiplied([w as usize, h as usize], &render(w, h));
        match slot {
            Some(c) => {
                c.texture.set(image, egui::TextureOptions::LINEAR);
                (c.camera, c.center) = (camera, center);
            }
            None => {
                *slot = Some(Closeup {
                    texture: ui
                        .ctx()
                        .load_texture(name, image, egui::TextureOptions::LINEAR),
                    camera,
                    center,
                })
            }
        }
    }
    if let Some(c) = slot {
        ui.painter().image(
            c.texture.id(),
            rect,
            Rect::from_min_max(Pos2::ZERO, Pos2::new(1.0, 1.0)),
            Color32::WHITE,
        );
    }
}
