//! The top bar (open a study) and the control strip on the left (flight, coverage, the
//! colon's segments and corrections, the submarine's settings, findings): every control
//! asks for an [`Action`], which [`App::apply`] carries out as a key would.

use std::path::PathBuf;

use egui::{Color32, RichText};
use voyage_core::LEFT_OUT_DOUBT_ML;
use voyage_nav::{Camera, Direction};
use voyage_view::{FindingKind, ReadingStep};

use super::{
    App, RESCUE_NOTICE_S,
    actions::{Action, Fly, Switch, Tool},
};
use crate::{
    gui::{
        corrections::{self, Correction},
        coverage::WindowCoverage,
        loader::Source,
    },
    open::InputArgs,
};

impl App {
    pub(super) fn top_bar(&mut self, ui: &mut egui::Ui) {
        let mut asked = None;
        egui::Panel::top("top").show(ui, |ui| {
            ui.horizontal(|ui| {
                ui.label(RichText::new("voyage").strong());
                if let Some(s) = &self.session {
                    ui.label(&s.exam.name);
                }
                ui.separator();
                ui.add(
                    egui::TextEdit::singleline(&mut self.open_path)
                        .hint_text("CT folder or file, or lumen mask")
                        .desired_width(260.0),
                );
                if ui.button("Open").clicked() && !self.open_path.trim().is_empty() {
                    asked = Some(Action::Open(Source::File(InputArgs {
                        input: PathBuf::from(self.open_path.trim()),
                        mask: false,
                        series: None,
                        points: Default::default(),
                    })));
                }
                if ui.button("Demo phantom").clicked() {
                    asked = Some(Action::Open(Source::Phantom {
                        small: false,
                        pair: false,
                        points: Default::default(),
                    }));
                }
                ui.separator();
                if ui.button("Help (H)").clicked() {
                    asked = Some(Action::ToggleHelp);
                }
                ui.label(RichText::new(&self.status).color(Color32::from_gray(170)));
            });
        });
        if let Some(action) = asked {
            self.apply(action, &ui.ctx().clone());
        }
    }

    pub(super) fn controls(&mut self, ui: &mut egui::Ui) {
        egui::Panel::left("controls")
            .resizable(false)
            .exact_size(236.0)
            .show(ui, |ui| {
                egui::ScrollArea::vertical().show(ui, |ui| self.control_contents(ui));
            });
    }

    fn control_contents(&mut self, ui: &mut egui::Ui) {
        let Some(s) = &mut self.session else {
            ui.label("No study open.");
            return;
        };
        let mut actions = Vec::new();
        ui.heading("Flight");
        ui.horizontal(|ui| {
            let text = if s.playing { "Pause" } else { "Play" };
            if ui.button(text).on_hover_text("Space").clicked() {
                actions.push(Action::Fly(Fly::PlayPause));
            }
            if ui.button("Start over").on_hover_text("Home").clicked() {
                actions.push(Action::Fly(Fly::Restart));
            }
        });
        let mut dir = s.direction();
        ui.radio_value(&mut dir, Direction::Forward, "rectum to cecum");
        ui.radio_value(&mut dir, Direction::Backward, "cecum to rectum");
        if dir != s.direction() {
            actions.push(Action::Fly(Fly::SetDirection(dir)));
        }
        if s.reached {
            match s.study.segmentation.largest_left_out(LEFT_OUT_DOUBT_ML) {
                Some(big) => ui.label(
                    RichText::new(format!(
                        "end of this colon reached, but {:.0} ml of gas ({}) was left out: is it colon? (see Colon)",
                        big.gas_ml, big.label
                    ))
                    .color(Color32::from_rgb(255, 190, 90)),
                ),
                None => ui.label(RichText::new("goal reached").color(Color32::LIGHT_GREEN)),
            };
        }
        ui.label(format!("to the goal: {:.0} mm", s.dt_to_goal()));
        if let Some(r) = s.pilot.recent_rescue(s.sub.state.t, RESCUE_NOTICE_S) {
            ui.label(
                RichText::new(format!(
                    "{} for {:.0} s at {:.0} mm along the colon: gliding on along the centerline",
                    r.cause(),
                    r.stuck_s,
                    r.arc_mm
                ))
                .color(Color32::from_rgb(255, 190, 90)),
            );
        }
        ui.separator();
        coverage_section(ui, &s.coverage, &mut actions);
        ui.separator();
        ui.heading("Colon");
        let busy = self.job.is_some();
        let mut asked = colon_summary(ui, &s.study, busy);
        let n = self
            .source
            .as_ref()
            .map_or(0, |x| corrections::count(x.points()));
        if let Some(job) = &self.job {
            ui.add(egui::ProgressBar::new(job.fraction()).text(format!("again: {}", job.what)));
        } else if n > 0
            && ui
                .button(format!(
                    "Undo {n} correction{}",
                    if n == 1 { "" } else { "s" }
                ))
                .on_hover_text("back to the colon found automatically")
                .clicked()
        {
            asked = Some(Correction::Reset);
        }
        if let Some(e) = &self.correction_error {
            ui.label(
                RichText::new(e)
                    .small()
                    .color(Color32::from_rgb(255, 140, 120)),
            );
        }
        ui.label(
            RichText::new("right click on a slice: start / end here, gas is colon or not")
                .small()
                .color(Color32::from_gray(150)),
        );
        actions.extend(asked.map(Action::Correct));
        ui.separator();
        ui.add(egui::Slider::new(&mut s.sub.potential.ct, 0.0..=1000.0).text("Ct (pull)"));
        ui.add(egui::Slider::new(&mut s.sub.potential.cs, 0.0..=1000.0).text("Cs (wall)"));
        let rho_hover = match s.opts.rho_per_radius {
            Some(k) => {
                format!("the reach of the wall's push; the flight keeps it within {k} lumen radii")
            }
            None => "the reach of the wall's push".to_string(),
        };
        ui.add(egui::Slider::new(&mut s.sub.potential.rho, 2.0..=60.0).text("ρ mm"))
            .on_hover_text(rho_hover);
        ui.add(egui::Slider::new(&mut s.sub.dynamics.user_force, 0.0..=2000.0).text("|F_user|"));
        ui.add(egui::Slider::new(&mut s.fov, 30.0..=Camera::MAX_FOV_DEG).text("FOV °"));
        for (switch, text, hover) in [
            (Switch::Compass, "compass (C)", None),
            (Switch::Leveling, "leveling (L)", None),
            (Switch::Still, "still (S)", None),
            (Switch::Centerline, "centerline (G)", None),
            (Switch::Closeup, "close-up volume (V)", None),
            (
                Switch::Translucency,
                "translucency (T)",
                Some("what lies beneath the surface around the marker or the view's centre"),
            ),
        ] {
            let mut on = self.switch(switch).is_some_and(|on| *on);
            let mut response = ui.checkbox(&mut on, text);
            if let Some(hover) = hover {
                response = response.on_hover_text(hover);
            }
            if response.changed() {
                actions.push(Action::Set(switch, on));
            }
        }
        ui.separator();
        ui.heading("Findings");
        let mut tool = self.tool;
        ui.horizontal(|ui| {
            ui.selectable_value(&mut tool, Tool::Steer, "Steer")
                .on_hover_text("1: hold the left button to push toward a point");
            ui.selectable_value(&mut tool, Tool::Marker, "Marker")
                .on_hover_text("2: click the surface (or M over it)");
            ui.selectable_value(&mut tool, Tool::Measure, "Measure")
                .on_hover_text("3: click two surface points (or D twice)");
            ui.selectable_value(&mut tool, Tool::Polyp, "Polyp")
                .on_hover_text("4: click a polyp (or P over it): its largest diameter, marked");
        });
        egui::ComboBox::from_label("kind of a new marker")
            .selected_text(self.marker_kind.name())
            .show_ui(ui, |ui| {
                for kind in FindingKind::ALL {
                    ui.selectable_value(&mut self.marker_kind, kind, kind.name());
                }
            });
        if tool != self.tool {
            actions.push(Action::Tool(tool));
        }
        ui.add(egui::TextEdit::singleline(&mut self.note).hint_text("note for the next marker"));
        for m in &self.findings.markers {
            ui.horizontal(|ui| {
                if ui
                    .button(&m.label)
                    .on_hover_text("fly back to this marker")
                    .clicked()
                {
                    actions.push(Action::GoToMarker(m.label.clone()));
                }
                let size = m.size_mm.map(|s| format!(" {s:.1} mm")).unwrap_or_default();
                ui.label(format!("{}{size}", m.kind.name()));
                ui.label(if m.note.is_empty() { "—" } else { &m.note });
                if let Some(o) = &self.other
                    && ui
                        .small_button(format!("show in {}", o.name()))
                        .on_hover_text(
                            "switch to the other position, where the link puts this marker",
                        )
                        .clicked()
                {
                    actions.push(Action::ShowInOther(m.label.clone()));
                }
                if ui.small_button("x").clicked() {
                    actions.push(Action::RemoveMarker(m.label.clone()));
                }
            });
        }
        if let Some(o) = &self.other {
            for m in &o.findings.markers {
                ui.horizontal(|ui| {
                    ui.label(format!("{}: {} {}", o.name(), m.label, m.kind.name()));
                    if ui
                        .small_button("show here")
                        .on_hover_text(
                            "look at where the link puts this marker in the position shown",
                        )
                        .clicked()
                    {
                        actions.push(Action::ShowHere(m.label.clone()));
                    }
                });
            }
        }
        for m in &self.findings.measurements {
            ui.horizontal(|ui| {
                ui.label(format!("{}: {:.1} mm", m.label, m.length_mm()));
                if ui.small_button("x").clicked() {
                    actions.push(Action::RemoveMeasurement(m.label.clone()));
                }
            });
        }
        ui.horizontal(|ui| {
            ui.add(egui::TextEdit::singleline(&mut self.export_dir).desired_width(120.0));
            if ui
                .button("Export")
                .on_hover_text("Ctrl+E: findings.json, Slicer .mrk.json and a PNG per marker")
                .clicked()
            {
                actions.push(Action::Export(None));
            }
        });
        let ctx = ui.ctx().clone();
        for action in actions {
            self.apply(action, &ctx);
        }
    }
}

/// The coverage read-out and its controls.
fn coverage_section(ui: &mut egui::Ui, c: &WindowCoverage, actions: &mut Vec<Action>) {
    ui.heading("Coverage");
    let o = c.session.options();
    ui.label(format!(
        "seen {:.1} % of the mucosa (this flight {:.1} %)",
        c.session.percent(),
        c.flight.percent()
    ))
    .on_hover_text(format!(
        "area of the surface shown within {:.0} mm, facing the camera within {:.0}°, since the study opened",
        o.reading_distance_mm, o.max_angle_deg
    ));
    if let Some(r) = &c.reading {
        let pct = |v: Option<f64>| v.map_or("…".to_string(), |x| format!("{x:.1} %"));
        let p = r.progress();
        let stage = match p.step {
            ReadingStep::Read(Direction::Forward) => {
                format!("rectum to cecum, {} glances", r.glances())
            }
            ReadingStep::Read(Direction::Backward) => {
                format!("cecum to rectum, {} glances", r.glances())
            }
            ReadingStep::Review(round) => format!(
                "review round {}: patch {} of {}",
                round + 1,
                p.done,
                p.total
            ),
            ReadingStep::Done => "done".to_string(),
        };
        ui.label(format!("two-way reading: {stage}"));
        if !r.is_done() {
            let fraction = p.done as f32 / p.total.max(1) as f32;
            ui.add(egui::ProgressBar::new(fraction).desired_width(200.0))
                .on_hover_text("W stops the reading");
        }
        ui.label(
            RichText::new(format!(
                "one way {} · both ways {} · after review {}",
                pct(r.one_way_pct()),
                pct(r.two_way_pct()),
                pct(r.after_review_pct())
            ))
            .small(),
        );
    }
    ui.horizontal(|ui| {
        if ui
            .button("Two-way reading")
            .on_hover_text("W: rectum to cecum, back, then every unseen patch")
            .clicked()
        {
            actions.push(Action::TwoWayReading);
        }
        if ui
            .button("Next unseen")
            .on_hover_text("N: fly to the largest unseen patch")
            .clicked()
        {
            actions.push(Action::NextUnseenPatch);
        }
    });
    let mut on = c.on;
    if ui
        .checkbox(&mut on, "mark what is shown")
        .on_hover_text("coverage tracking; unseen mucosa is blue on the scout")
        .changed()
    {
        actions.push(Action::Set(Switch::Coverage, on));
    }
}

/// The colon's segments, bridged gaps, the patient's position and the warnings, as
/// preprocessing reported them. Each segment has a box to take it in or leave it out; the
/// correction asked for, if any, is returned (`busy`: one is being preprocessed).
fn colon_summary(ui: &mut egui::Ui, study: &voyage_core::Study, busy: bool) -> Option<Correction> {
    let seg = &study.segmentation;
    let o = &seg.orientation;
    let kept = seg.segments.iter().filter(|s| s.kept).count();
    ui.label(format!(
        "{} ({}, {})",
        o.position.code(),
        o.position.describe(),
        o.source.describe()
    ));
    let mut asked = None;
    egui::CollapsingHeader::new(format!("{kept} colon segment{} of {} gas regions", if kept == 1 { "" } else { "s" }, seg.segments.len()))
        .id_salt("segments")
        .default_open(seg.segments.len() <= 8)
        .show(ui, |ui| {
            ui.add_enabled_ui(!busy, |ui| {
                for s in &seg.segments {
                    let mut on = s.kept;
                    let text = if s.fluid_ml >= 0.5 {
                        format!("{}, {:.0} ml gas + {:.0} ml fluid", s.label, s.gas_ml, s.fluid_ml)
                    } else {
                        format!("{}, {:.0} ml gas", s.label, s.gas_ml)
                    };
                    let why = s.reason.as_deref().unwrap_or("in the colon");
                    let a = s.anchor_lps_mm;
                    let hover = format!("{why}\nuntick to leave it out, tick to take it in\nLPS ({:.0}, {:.0}, {:.0}) mm", a[0], a[1], a[2]);
                    if ui.checkbox(&mut on, text).on_hover_text(hover).changed() {
                        asked = Some(if on { Correction::Include(a) } else { Correction::Exclude(a) });
                    }
                }
            });
        });
    for (gap, span) in seg.gaps.iter().zip(&study.gap_spans) {
        let names = |i: usize| {
            seg.segments
                .iter()
                .find(|s| s.order == Some(i))
                .map_or("?", |s| s.label.as_str())
        };
        let at = span.map_or(String::new(), |a| format!(" at {:.0} mm", a[0]));
        ui.label(format!(
            "{} – {} gap {:.0} mm bridged{at}",
            names(gap.between[0]),
            names(gap.between[1]),
            gap.length_mm
        ));
    }
    if !seg.warnings.is_empty() {
        egui::CollapsingHeader::new(
            RichText::new(format!(
                "{} warning{}",
                seg.warnings.len(),
                if seg.warnings.len() == 1 { "" } else { "s" }
            ))
            .color(Color32::from_rgb(255, 190, 120)),
        )
        .id_salt("warnings")
        .show(ui, |ui| {
            for w in &seg.warnings {
                ui.label(RichText::new(w).small());
            }
        });
    }
    asked
}
