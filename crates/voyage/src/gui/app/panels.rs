//! The scout, the slices and the endoscopic view with its mouse: each panel shows the
//! study, and what is clicked on it becomes an [`Action`].

use egui::{Color32, Rect, RichText, Sense, Vec2};
use glam::DVec3;
use voyage_nav::Input;

use super::{
    App,
    actions::{Action, Tool, ViewPoint},
};
use crate::gui::{
    endoscopy::ray_at,
    positions::Other,
    scout::{ScoutClick, ScoutMarks, ScoutView},
    slices::{SliceAction, SliceSource},
};

/// Input gathered for the submarine this frame.
#[derive(Default)]
struct Steering {
    /// Ray toward the point held (F_user).
    push: Option<DVec3>,
    /// Right-drag in points this frame (τ_option).
    look: Vec2,
}

/// The other position's scout, its linked place marked (clicks there do nothing: the
/// position is not shown).
fn other_scout(ui: &mut egui::Ui, o: &Other, view: &mut ScoutView) {
    let s = &o.session;
    let here = o.linked.unwrap_or_else(|| s.pose().position);
    let marks = ScoutMarks {
        centerline: &s.study.centerline.points_mm,
        arc_mm: &s.study.centerline.arc_mm,
        markers: std::iter::once(("here".to_string(), here))
            .chain(
                o.findings
                    .markers
                    .iter()
                    .map(|m| (m.label.clone(), m.position)),
            )
            .collect(),
        submarine: here,
        view_dir: s.pose().z_body(),
        unseen: None,
    };
    let _ = view.show(ui, &s.scout, &marks);
}

impl App {
    pub(super) fn scout_panel(&mut self, ui: &mut egui::Ui) {
        egui::Panel::right("scout")
            .resizable(false)
            .exact_size(360.0)
            .show(ui, |ui| {
                // With two positions open, the other's scout below shows where the camera's
                // place lies in it, moving as the camera moves.
                if let (Some(o), Some(view)) = (&self.other, &mut self.other_scout) {
                    let height = 0.42 * ui.available_height();
                    egui::Panel::bottom("other position")
                        .resizable(false)
                        .exact_size(height)
                        .show(ui, |ui| {
                            ui.label(format!("{}: the same place", o.name()));
                            other_scout(ui, o, view);
                        });
                }
                let (Some(s), Some(view)) = (&mut self.session, &mut self.scout) else {
                    ui.label("scout");
                    return;
                };
                let pose = s.pose();
                let unseen = s
                    .coverage
                    .on
                    .then(|| s.coverage.scout_tint(&s.mesh, &s.scout));
                let marks = ScoutMarks {
                    centerline: &s.study.centerline.points_mm,
                    arc_mm: &s.study.centerline.arc_mm,
                    markers: self
                        .findings
                        .markers
                        .iter()
                        .map(|m| (m.label.clone(), m.position))
                        .chain(self.looked_up.clone())
                        .collect(),
                    submarine: pose.position,
                    view_dir: pose.z_body(),
                    unseen,
                };
                match view.show(ui, &s.scout, &marks) {
                    Some(ScoutClick::Missed(d)) => {
                        self.status = format!(
                            "the click on the scout missed the centerline ({d:.0} px away): click on the green line (it lights up under the pointer); drag orbits"
                        );
                    }
                    Some(ScoutClick::Centerline(i)) => {
                        self.apply(Action::JumpToCenterline(i), &ui.ctx().clone())
                    }
                    None => {}
                }
            });
    }

    pub(super) fn slice_panel(&mut self, ui: &mut egui::Ui) {
        egui::Panel::bottom("slices")
            .resizable(false)
            .exact_size(262.0)
            .show(ui, |ui| {
                let Some(s) = &mut self.session else { return };
                let at = s.pose().position;
                let p = s.study.segmentation.orientation.position;
                let position = format!("{} ({})", p.describe(), p.code());
                match self.slices.show(
                    ui,
                    SliceSource {
                        ct: &s.study.ct,
                        cleansing: &s.study.cleansing,
                        position: &position,
                    },
                    at,
                    self.job.is_some(),
                ) {
                    Some(SliceAction::MoveTo(p)) => {
                        self.apply(Action::MoveTo(p), &ui.ctx().clone())
                    }
                    Some(SliceAction::Correct(c)) => {
                        self.apply(Action::Correct(c), &ui.ctx().clone())
                    }
                    None => {}
                }
            });
    }

    pub(super) fn endoscopy_panel(&mut self, ui: &mut egui::Ui, frame: &eframe::Frame, dt: f64) {
        egui::CentralPanel::default()
            .frame(egui::Frame::NONE)
            .show(ui, |ui| {
                if self.session.is_none() {
                    self.waiting(ui);
                    return;
                }
                let (rect, response) =
                    ui.allocate_exact_size(ui.available_size(), Sense::click_and_drag());
                self.view_rect = Some(rect);
                let steering = self.steering(ui, rect, &response);
                let Some(s) = &mut self.session else { return };
                let cam = s.camera();
                let mut input = Input::default();
                if let Some(ray) = steering.push {
                    input.force = s.sub.push_toward(&s.field, ray);
                }
                if steering.look != Vec2::ZERO {
                    // τ_option from the drag: the turn rate that keeps the view under the pointer
                    // (fov per view height), held against the angular friction ka.
                    let rad_per_point = s.fov.to_radians() / rect.height().max(1.0) as f64;
                    let rate = DVec3::new(steering.look.x as f64, steering.look.y as f64, 0.0)
                        * rad_per_point
                        / dt.max(1e-3);
                    let p = cam.pose;
                    input.torque = (-p.y_body() * rate.x + p.x_body() * rate.y) * s.sub.dynamics.ka;
                }
                s.step(dt, &input);
                if let Some(o) = &mut self.other {
                    o.follow(s);
                }

                let ppp = ui.ctx().pixels_per_point();
                let size = [
                    ((rect.width() * ppp).round() as u32).max(16),
                    ((rect.height() * ppp).round() as u32).max(16),
                ];
                let rs = frame.wgpu_render_state();
                if let Err(e) =
                    self.endoscope
                        .render(ui.painter(), rect, rs, s, self.generation, size)
                {
                    self.status = format!("rendering failed: {e:#}");
                }
                self.last_cells = self.endoscope.last_cells.clone();
                self.times.record_render(self.endoscope.stats.render_ms);
                s.mark_shown(&s.camera(), size, self.times.last_frame_ms());
                if let Err(e) = s.step_reading() {
                    s.stop_reading();
                    self.status = format!("the two-way reading stopped: {e}");
                }
                self.closeup_overlay(ui, rect);
                self.translucency_overlay(ui, rect);
                self.overlays(ui, rect);
            });
    }

    /// The mouse on the view: steering, looking, markers and measurements.
    fn steering(&mut self, ui: &egui::Ui, rect: Rect, response: &egui::Response) -> Steering {
        let mut out = Steering::default();
        let Some(s) = &self.session else { return out };
        let cam = s.camera();
        let primary_down =
            response.is_pointer_button_down_on() && ui.input(|i| i.pointer.primary_down());
        if self.tool == Tool::Steer
            && primary_down
            && let Some(p) = ui.input(|i| i.pointer.interact_pos())
        {
            out.push = Some(ray_at(&cam, rect, p));
        }
        if response.dragged_by(egui::PointerButton::Secondary) {
            out.look = response.drag_delta();
        }
        if let Some((at, frames)) = self.steer_script {
            out.push = Some(ray_at(
                &cam,
                rect,
                rect.min + Vec2::new(at[0], at[1]) * rect.size(),
            ));
            self.steer_script = (frames > 1).then_some((at, frames - 1));
        }
        if let Some((d, frames)) = self.look_script {
            out.look = d;
            self.look_script = (frames > 1).then_some((d, frames - 1));
        }
        if response.clicked()
            && let Some(p) = response.interact_pointer_pos()
        {
            let at = ViewPoint::At(p);
            let action = match self.tool {
                Tool::Marker => Some(Action::Marker {
                    at,
                    note: None,
                    kind: None,
                }),
                Tool::Measure => Some(Action::MeasurePoint(at)),
                Tool::Polyp => Some(Action::Polyp { at, note: None }),
                Tool::Steer => None,
            };
            if let Some(action) = action {
                self.apply(action, &ui.ctx().clone());
            }
        }
        out
    }

    /// The view while nothing is open yet: progress, or the error and what to do.
    pub(super) fn waiting(&mut self, ui: &mut egui::Ui) {
        ui.add_space(ui.available_height() * 0.35);
        ui.vertical_centered(|ui| {
            if let Some(job) = &self.job {
                ui.heading(format!("Opening {}", job.source.describe()));
                ui.add(egui::ProgressBar::new(job.fraction()).desired_width(360.0).text(format!("{} ({}/{})", job.what, job.step + 1, job.of)));
                ui.label(format!("{:.1} s", job.started.elapsed().as_secs_f64()));
            } else if let Some(e) = &self.error {
                ui.heading(RichText::new("Could not open the study").color(Color32::from_rgb(255, 120, 100)));
                ui.label(RichText::new(e).color(Color32::from_rgb(255, 170, 150)));
                ui.label("Open another CT or mask with the field above, or the demo phantom.");
            } else {
                ui.heading("No study open");
                ui.label("Give a CT folder or file (or a lumen mask) above and press Open, or open the demo phantom.");
            }
        });
    }
}
