//! What the user asks of the window ([`Action`]), from a key of the [`KEYMAP`], a control or
//! a script step, and [`App::apply`], which carries it out: the three ways in go through one
//! door, so they cannot disagree.

use std::path::PathBuf;

use egui::{Key, Modifiers, Pos2, Vec2};
use glam::DVec3;
use voyage_export::{PositionReading, ReportCoverage, export_pair_reading, export_reading};
use voyage_nav::{Camera, Direction};
use voyage_view::{FindingKind, Findings, Hit, MucosaMap, both_coverage, pick};

use super::{App, note_error};
use crate::gui::{
    corrections::Correction,
    endoscopy::ray_at,
    loader::Source,
    positions::{look_at, switch},
    session::Session,
};

/// What a click on the endoscopic view does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Tool {
    /// Click and hold: push the submarine toward the point (F_user).
    Steer,
    /// Click: a marker on the surface point.
    Marker,
    /// Two clicks: the distance between two surface points.
    Measure,
    /// Click a polyp: it is segmented, its largest diameter measured, and it becomes a
    /// polyp finding with that size.
    Polyp,
}

/// A point of the endoscopic view an action is about.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum ViewPoint {
    /// Under the mouse cursor (nothing when the cursor is off the view).
    Cursor,
    /// Where the mouse clicked, in window points.
    At(Pos2),
    /// Fractions of the view's width and height from its top-left corner (scripts).
    Fraction([f32; 2]),
}

/// What the user asks of the window, from a key, a control or a script: [`App::apply`]
/// carries it out, so the three cannot disagree.
#[derive(Clone, Debug)]
pub(super) enum Action {
    Quit,
    /// Export the findings into a folder (none: the folder named in the controls).
    Export(Option<PathBuf>),
    /// Open a study (replacing the one open).
    Open(Source),
    ToggleHelp,
    /// Close the help, cancel a measurement.
    Cancel,
    Toggle(Switch),
    Set(Switch, bool),
    Tool(Tool),
    Fly(Fly),
    /// A marker on the surface at a point of the view; the note and kind, where not given,
    /// are the controls' (the note field is emptied).
    Marker {
        at: ViewPoint,
        note: Option<String>,
        kind: Option<FindingKind>,
    },
    /// Size the polyp at a point of the view and mark it.
    Polyp {
        at: ViewPoint,
        note: Option<String>,
    },
    /// One end of a measurement (the first, or the second of the one begun).
    MeasurePoint(ViewPoint),
    /// A whole measurement between two points of the view.
    MeasureBetween(ViewPoint, ViewPoint),
    RemoveMarker(String),
    RemoveMeasurement(String),
    /// Fly back to a marker, by label.
    GoToMarker(String),
    /// Switch to the other position where the link puts a marker of the one shown (by
    /// label); a marker of the other position is looked up in the one shown instead.
    ShowInOther(String),
    /// Look at where the link puts a marker of the other position in the one shown.
    ShowHere(String),
    /// To a point of the centerline: a fraction of its length from the rectum.
    Jump(f64),
    /// To a point of the centerline, by index (a click on the scout).
    JumpToCenterline(usize),
    /// To a viewing spot near a point (volume-local mm), looking down the colon (a click on
    /// a slice).
    MoveTo(DVec3),
    /// The same with the point in LPS mm.
    MoveToLps(DVec3),
    /// The camera at a pose [x, y, z, qw, qx, qy, qz] (volume-local mm), if it lies inside
    /// the colon.
    Pose([f64; 7]),
    /// Rectum → cecum, cecum → rectum, then every unseen patch (issue 23).
    TwoWayReading,
    /// Fly to the largest unseen patch and outline it.
    NextUnseenPatch,
    /// Show the exam's other position at the same place (issue 39).
    SwitchPosition,
    /// Correct the colon found and preprocess again.
    Correct(Correction),
}

/// What the user asks of the flight and the camera's lens.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Fly {
    PlayPause,
    Play(bool),
    Reverse,
    SetDirection(Direction),
    /// Back to the start of the flight.
    Restart,
    NarrowerView,
    WiderView,
}

/// The window's on/off settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Switch {
    Centerline,
    Closeup,
    Translucency,
    Compass,
    Leveling,
    Still,
    /// Coverage marking of the frames shown.
    Coverage,
    /// The slices show the cleansed CT (a tagged exam).
    SlicesCleansed,
    /// The slices outline what cleansing changed.
    SlicesOutline,
}

const NONE: Modifiers = Modifiers::NONE;
const CTRL: Modifiers = Modifiers::COMMAND;

/// One row of the help: what it says, and the keys that do it (none for the mouse's rows).
struct Binding {
    keys: &'static str,
    what: &'static str,
    bound: &'static [(Modifiers, Key, Action)],
}

/// The keymap: [`App::shortcuts`] dispatches from it and the help shows it.
const KEYMAP: &[Binding] = &[
    Binding {
        keys: "Space",
        what: "play / pause the automatic flight",
        bound: &[(NONE, Key::Space, Action::Fly(Fly::PlayPause))],
    },
    Binding {
        keys: "R",
        what: "reverse the direction (rectum / cecum)",
        bound: &[(NONE, Key::R, Action::Fly(Fly::Reverse))],
    },
    Binding {
        keys: "Home",
        what: "back to the start of the flight",
        bound: &[(NONE, Key::Home, Action::Fly(Fly::Restart))],
    },
    Binding {
        keys: "left button (hold)",
        what: "push the submarine toward that point",
        bound: &[],
    },
    Binding {
        keys: "right button (drag)",
        what: "look around",
        bound: &[],
    },
    Binding {
        keys: "O",
        what: "the exam's other position (supine / prone), at the same place",
        bound: &[(NONE, Key::O, Action::SwitchPosition)],
    },
    Binding {
        keys: "M",
        what: "marker on the surface under the cursor",
        bound: &[(
            NONE,
            Key::M,
            Action::Marker {
                at: ViewPoint::Cursor,
                note: None,
                kind: None,
            },
        )],
    },
    Binding {
        keys: "P",
        what: "polyp under the cursor: segment it, measure its largest diameter, mark it",
        bound: &[(
            NONE,
            Key::P,
            Action::Polyp {
                at: ViewPoint::Cursor,
                note: None,
            },
        )],
    },
    Binding {
        keys: "D",
        what: "measure: press on two surface points",
        bound: &[(NONE, Key::D, Action::MeasurePoint(ViewPoint::Cursor))],
    },
    Binding {
        keys: "1 / 2 / 3 / 4",
        what: "tool: steer / marker / measure / polyp size (for the left button)",
        bound: &[
            (NONE, Key::Num1, Action::Tool(Tool::Steer)),
            (NONE, Key::Num2, Action::Tool(Tool::Marker)),
            (NONE, Key::Num3, Action::Tool(Tool::Measure)),
            (NONE, Key::Num4, Action::Tool(Tool::Polyp)),
        ],
    },
    Binding {
        keys: "C / L / S",
        what: "compass / leveling / still mode",
        bound: &[
            (NONE, Key::C, Action::Toggle(Switch::Compass)),
            (NONE, Key::L, Action::Toggle(Switch::Leveling)),
            (NONE, Key::S, Action::Toggle(Switch::Still)),
        ],
    },
    Binding {
        keys: "W",
        what: "two-way reading: rectum to cecum, back, then every unseen patch",
        bound: &[(NONE, Key::W, Action::TwoWayReading)],
    },
    Binding {
        keys: "N",
        what: "next unseen patch (largest first), outlined in orange",
        bound: &[(NONE, Key::N, Action::NextUnseenPatch)],
    },
    Binding {
        keys: "G",
        what: "centerline overlay (green)",
        bound: &[(NONE, Key::G, Action::Toggle(Switch::Centerline))],
    },
    Binding {
        keys: "V",
        what: "close-up volume rendering",
        bound: &[(NONE, Key::V, Action::Toggle(Switch::Closeup))],
    },
    Binding {
        keys: "T",
        what: "translucency: what lies beneath the surface (red soft tissue, yellow fat, green stool)",
        bound: &[(NONE, Key::T, Action::Toggle(Switch::Translucency))],
    },
    Binding {
        keys: "[ / ]",
        what: "narrower / wider field of view",
        bound: &[
            (NONE, Key::OpenBracket, Action::Fly(Fly::NarrowerView)),
            (NONE, Key::CloseBracket, Action::Fly(Fly::WiderView)),
        ],
    },
    Binding {
        keys: "Ctrl+E",
        what: "export the findings",
        bound: &[(CTRL, Key::E, Action::Export(None))],
    },
    Binding {
        keys: "H or F1",
        what: "this help",
        bound: &[
            (NONE, Key::H, Action::ToggleHelp),
            (NONE, Key::F1, Action::ToggleHelp),
        ],
    },
    Binding {
        keys: "Esc",
        what: "close the help, cancel a measurement",
        bound: &[(NONE, Key::Escape, Action::Cancel)],
    },
    Binding {
        keys: "Ctrl+Q",
        what: "quit",
        bound: &[(CTRL, Key::Q, Action::Quit)],
    },
];

/// The reading's figures of session `s`, as `voyage report` gives them on the same study
/// (one engine).
fn report_coverage(s: &Session) -> ReportCoverage {
    let reading = s.coverage.reading.as_ref();
    ReportCoverage {
        session_pct: Some(s.coverage.session.percent()),
        one_way_pct: reading.and_then(|r| r.one_way_pct()),
        two_way_pct: reading.and_then(|r| r.two_way_pct()),
        after_review_pct: reading.and_then(|r| r.after_review_pct()),
        patches_left: reading
            .filter(|r| r.is_done())
            .map(|r| r.seen().patches(&s.mesh).len()),
        // Per segment, the figure the category reads: after the review, else the session.
        by_segment: reading
            .filter(|r| r.is_done())
            .map_or(&s.coverage.session, |r| r.seen())
            .by_segment(&s.mesh, &s.study),
    }
}

/// Session `s` with its `findings`, for the report over both positions.
fn position_reading<'a>(s: &'a Session, findings: &'a Findings) -> PositionReading<'a> {
    PositionReading {
        name: crate::open::position_of(&s.study),
        study: &s.study,
        exam: &s.exam,
        findings,
        coverage: report_coverage(s),
    }
}

/// Marker `m`'s view in session `s`, drawn again for the export (512², RGBA).
fn snapshot(s: &Session, m: &voyage_view::Marker) -> voyage_core::Result<(u32, u32, Vec<u8>)> {
    let cam = Camera::new(m.view).with_fov(s.fov);
    let cells = voyage_view::Visibility::new(&s.study.cells, voyage_view::Strategy::Lg)
        .select(&s.study.cells, &voyage_view::View::new(&cam, 512, 512))
        .cells;
    Ok((
        512,
        512,
        voyage_view::render_rgba(
            &s.mesh,
            &cam,
            &cells,
            512,
            512,
            &voyage_view::Lighting::default(),
        ),
    ))
}

impl App {
    /// Keyboard shortcuts from [`KEYMAP`] (not while a text field has the keyboard).
    pub(super) fn shortcuts(&mut self, ctx: &egui::Context) {
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        for binding in KEYMAP {
            for (modifiers, key, action) in binding.bound {
                if ctx.input_mut(|i| i.consume_key(*modifiers, *key)) {
                    self.apply(action.clone(), ctx);
                }
            }
        }
    }

    /// The keys and the mouse, as the [`KEYMAP`] has them.
    pub(super) fn help(&mut self, ctx: &egui::Context) {
        let mut open = self.show_help;
        egui::Window::new("Keys and mouse")
            .open(&mut open)
            .collapsible(false)
            .resizable(false)
            .anchor(egui::Align2::CENTER_CENTER, Vec2::ZERO)
            .show(ctx, |ui| {
                egui::Grid::new("keys").striped(true).show(ui, |ui| {
                    for binding in KEYMAP {
                        ui.label(egui::RichText::new(binding.keys).strong());
                        ui.label(binding.what);
                        ui.end_row();
                    }
                });
            });
        self.show_help &= open;
    }

    /// Carries out what a key, a control or a script asked. Actions on the flight wait for
    /// a study; the ones at a point of the view need that point in the view.
    pub(super) fn apply(&mut self, action: Action, ctx: &egui::Context) {
        match action {
            Action::Quit => self.quit(ctx),
            Action::Export(dir) => {
                let dir = dir.unwrap_or_else(|| PathBuf::from(self.export_dir.clone()));
                self.export(dir)
            }
            Action::Open(source) => self.open(source, ctx),
            Action::ToggleHelp => self.show_help = !self.show_help,
            Action::Cancel => {
                self.show_help = false;
                self.measure_from = None;
            }
            Action::Toggle(switch) => {
                if let Some(on) = self.switch(switch) {
                    *on = !*on;
                }
            }
            Action::Set(switch, value) => {
                if let Some(on) = self.switch(switch) {
                    *on = value;
                }
            }
            Action::Tool(tool) => self.tool = tool,
            Action::Marker { at, note, kind } => {
                if let Some(p) = self.view_point(at, ctx) {
                    self.drop_marker(p, note, kind);
                }
            }
            Action::Polyp { at, note } => {
                if let Some(p) = self.view_point(at, ctx) {
                    self.size_polyp(p, note);
                }
            }
            Action::MeasurePoint(at) => {
                if let Some(p) = self.view_point(at, ctx) {
                    self.measure_point(p);
                }
            }
            Action::MeasureBetween(a, b) => {
                if let (Some(a), Some(b)) = (self.view_point(a, ctx), self.view_point(b, ctx)) {
                    self.measure_from = None;
                    self.measure_point(a);
                    self.measure_point(b);
                }
            }
            Action::RemoveMarker(label) => {
                self.findings.remove_marker(&label);
            }
            Action::RemoveMeasurement(label) => {
                self.findings.remove_measurement(&label);
            }
            Action::GoToMarker(label) => self.go_to_marker(&label),
            Action::ShowInOther(label) => self.show_in_other(&label),
            Action::ShowHere(label) => {
                if !self.show_other_marker_here(&label) {
                    self.status = format!("no marker {label} in the other position");
                }
            }
            Action::SwitchPosition => {
                self.switch_position();
            }
            Action::TwoWayReading => self.two_way_reading(),
            Action::NextUnseenPatch => self.next_unseen_patch(),
            Action::Correct(c) => self.correct(c, ctx),
            Action::Jump(f) => self.jump(f),
            Action::JumpToCenterline(i) => self.jump_to_centerline(i),
            Action::MoveTo(x) => self.move_to_point(x),
            Action::MoveToLps(lps) => {
                if let Some(s) = &mut self.session {
                    let x = s.study.ct.geometry().patient_to_local(lps);
                    s.set_playing(false);
                    self.move_to_point(x);
                }
            }
            Action::Pose(a) => self.pose(a),
            Action::Fly(fly) => self.fly(fly),
        }
    }

    /// The actions on the flight and the camera's lens.
    fn fly(&mut self, fly: Fly) {
        let Some(s) = &mut self.session else { return };
        match fly {
            Fly::PlayPause => s.set_playing(!s.playing),
            Fly::Play(on) => s.set_playing(on),
            Fly::Reverse => s.set_direction(s.direction().reversed()),
            Fly::SetDirection(d) => s.set_direction(d),
            Fly::Restart => s.restart(),
            Fly::NarrowerView => s.fov = (s.fov - 5.0).max(30.0),
            Fly::WiderView => s.fov = (s.fov + 5.0).min(Camera::MAX_FOV_DEG),
        }
    }

    /// The point of the view an action is about, if it lies in the view (else says so,
    /// unless it is the cursor: a key pressed with the cursor elsewhere does nothing).
    fn view_point(&mut self, at: ViewPoint, ctx: &egui::Context) -> Option<Pos2> {
        let rect = self.view_rect?;
        let p = match at {
            ViewPoint::Cursor => ctx.input(|i| i.pointer.hover_pos())?,
            ViewPoint::At(p) => p,
            ViewPoint::Fraction(f) => rect.min + Vec2::new(f[0], f[1]) * rect.size(),
        };
        let inside = rect.contains(p);
        if !inside && at != ViewPoint::Cursor {
            self.status = "the point lies outside the view".into();
        }
        inside.then_some(p)
    }

    /// Starts the two-way reading, or stops the one running.
    fn two_way_reading(&mut self) {
        let Some(s) = &mut self.session else { return };
        if s.coverage.reading_running() {
            s.stop_reading();
            self.status = "two-way reading stopped".into();
        } else {
            s.coverage.on = true;
            self.status = match s.start_reading() {
                Ok(()) => "two-way reading started".into(),
                Err(e) => format!("the two-way reading cannot start: {e}"),
            };
        }
    }

    /// To the point of the centerline a fraction `f` of its length from the rectum.
    fn jump(&mut self, f: f64) {
        let Some(s) = &self.session else { return };
        let n = s.study.centerline.points_mm.len();
        let i = (f.clamp(0.0, 1.0) * n.saturating_sub(1) as f64).round() as usize;
        self.jump_to_centerline(i);
    }

    fn jump_to_centerline(&mut self, i: usize) {
        let Some(s) = &mut self.session else { return };
        match s.jump_to_centerline(i) {
            Ok(()) => {
                self.slices.follow();
                self.status = format!(
                    "jumped to {:.0} mm along the centerline",
                    s.study.centerline.arc_mm.get(i).copied().unwrap_or(0.0)
                );
            }
            Err(e) => self.status = e,
        }
    }

    fn pose(&mut self, a: [f64; 7]) {
        let (Some(s), Some(p)) = (&mut self.session, voyage_nav::Pose::from_array(a)) else {
            return;
        };
        if s.sub.is_safe(&s.field, p.position) {
            s.set_playing(false);
            s.place(p);
            self.slices.follow();
        } else {
            self.status = "the pose asked for is not inside the colon".into();
        }
    }

    /// Flies to the largest unseen patch, or says why not.
    fn next_unseen_patch(&mut self) {
        let Some(s) = &mut self.session else { return };
        let Some((patch, pose)) = s.coverage.next_patch(&s.mesh, &s.study) else {
            self.status = format!(
                "no unseen patch of {:.0} mm² or more is left",
                s.coverage.session.options().min_patch_mm2
            );
            return;
        };
        let arc = patch.arc_mm(&s.study).unwrap_or(0.0);
        self.status = match pose {
            Some(p) if s.show_from(p) => {
                self.slices.follow();
                format!(
                    "unseen patch: {:.0} mm², {:.0} mm across, {:.0} mm along the centerline",
                    patch.area_mm2, patch.across_mm, arc
                )
            }
            _ => format!(
                "the largest unseen patch ({:.0} mm², {:.0} mm along the centerline) has no viewpoint in the lumen that sees it",
                patch.area_mm2, arc
            ),
        };
    }

    /// The setting behind a switch (the submarine's modes only while a study is open).
    pub(super) fn switch(&mut self, switch: Switch) -> Option<&mut bool> {
        Some(match switch {
            Switch::Centerline => &mut self.show_centerline,
            Switch::Closeup => &mut self.boxes.closeup_on,
            Switch::Translucency => &mut self.boxes.translucency_on,
            Switch::Compass => &mut self.session.as_mut()?.sub.modes.compass,
            Switch::Leveling => &mut self.session.as_mut()?.sub.modes.leveling,
            Switch::Still => &mut self.session.as_mut()?.sub.modes.still,
            Switch::Coverage => &mut self.session.as_mut()?.coverage.on,
            Switch::SlicesCleansed => &mut self.slices.cleansed,
            Switch::SlicesOutline => &mut self.slices.outline,
        })
    }

    fn quit(&mut self, ctx: &egui::Context) {
        self.quitting = true;
        ctx.send_viewport_cmd(egui::ViewportCommand::Close);
    }

    /// The surface point under a point of the view (searching the cells last drawn first).
    pub(super) fn pick(&self, at: Pos2) -> Option<Hit> {
        let (s, rect) = (self.session.as_ref()?, self.view_rect?);
        let cam = s.camera();
        let ray = ray_at(&cam, rect, at);
        pick(&s.mesh, Some(&self.last_cells), cam.pose.position, ray)
            .or_else(|| pick(&s.mesh, None, cam.pose.position, ray))
    }

    /// A marker on the surface under `at`: of `kind` with `note`, else of the kind and
    /// with the note the controls hold.
    fn drop_marker(&mut self, at: Pos2, note: Option<String>, kind: Option<FindingKind>) {
        let Some(hit) = self.pick(at) else {
            self.status = "no surface under the cursor".into();
            return;
        };
        let Some(s) = &self.session else { return };
        let note = note.unwrap_or_else(|| std::mem::take(&mut self.note));
        let kind = kind.unwrap_or(self.marker_kind);
        let label = self
            .findings
            .add_marker(hit.point, hit.normal, s.pose(), note)
            .label
            .clone();
        if let Some(m) = self.findings.marker_mut(&label) {
            m.kind = kind;
        }
        self.status = format!("marker {label} at {:.1} mm from the camera", hit.distance);
    }

    /// Segments the polyp under `at`, measures its largest diameter and marks it as a polyp
    /// of that size; says so when nothing stands out of the wall there.
    fn size_polyp(&mut self, at: Pos2, note: Option<String>) {
        let Some(hit) = self.pick(at) else {
            self.status = "no surface under the cursor".into();
            return;
        };
        let Some(s) = &self.session else { return };
        let Some(size) = voyage_view::measure_polyp(&s.mesh, hit.point, hit.normal) else {
            self.status = "no polyp there: nothing stands out of the wall under the cursor (or it is over 4 cm)".into();
            return;
        };
        let note = note.unwrap_or_else(|| std::mem::take(&mut self.note));
        let pose = s.pose();
        let label = self
            .findings
            .add_marker(hit.point, hit.normal, pose, note)
            .label
            .clone();
        if let Some(m) = self.findings.marker_mut(&label) {
            m.kind = FindingKind::Polyp;
            m.size_mm = Some(size.diameter_mm);
        }
        self.polyp_span = Some(size.ends);
        self.status = format!(
            "polyp {label}: {:.1} mm (largest diameter), {:.1} mm high",
            size.diameter_mm, size.height_mm
        );
    }

    fn measure_point(&mut self, at: Pos2) {
        let Some(hit) = self.pick(at) else {
            self.status = "no surface under the cursor".into();
            return;
        };
        match self.measure_from.take() {
            None => {
                self.measure_from = Some(hit.point);
                self.status = "measure: now the second point".into();
            }
            Some(a) => {
                let label = self.findings.add_measurement(a, hit.point).label.clone();
                self.status = format!("{label}: {:.1} mm", a.distance(hit.point));
            }
        }
    }

    fn export(&mut self, dir: PathBuf) {
        let Some(s) = &self.session else {
            self.status = "nothing to export: no study is open".into();
            return;
        };
        let result = match &self.other {
            None => export_reading(
                &dir,
                &self.findings,
                &s.study,
                &s.exam,
                report_coverage(s),
                |_, m| snapshot(s, m),
            ),
            // Both positions: each into a folder of its name, the report over both beside.
            Some(o) => {
                // Supine first, as `voyage report` lists them, whichever is shown.
                let shown = (s, &self.findings);
                let waiting = (&o.session, &o.findings);
                let prone_shown = crate::open::position_of(&s.study) == "prone";
                let ((a, fa), (b, fb), link) = if prone_shown {
                    (waiting, shown, o.link.reversed())
                } else {
                    (shown, waiting, o.link.clone())
                };
                let (map_a, map_b) = (
                    MucosaMap::of(&a.study, &a.mesh),
                    MucosaMap::of(&b.study, &b.mesh),
                );
                let both = both_coverage(
                    &link,
                    &voyage_view::Read {
                        study: &a.study,
                        map: &map_a,
                        seen: &a.coverage.session,
                    },
                    &voyage_view::Read {
                        study: &b.study,
                        map: &map_b,
                        seen: &b.coverage.session,
                    },
                );
                export_pair_reading(
                    &dir,
                    position_reading(a, fa),
                    position_reading(b, fb),
                    &link,
                    &[("whole session", both)],
                    |p, _, m| snapshot(if p == 0 { a } else { b }, m),
                )
            }
        };
        match result {
            Ok(files) => {
                // Where the files went, in full: a relative folder is relative to where
                // voyage was started, which the window does not show.
                let at = std::path::absolute(&dir).unwrap_or(dir);
                self.status = format!("exported {} files to {}", files.len(), at.display())
            }
            Err(e) => {
                self.status = format!("export failed: {e}");
                note_error(&self.outcome, format!("export: {e}"));
            }
        }
    }

    /// Shows the exam's other position, standing where the camera's place lies in it; what
    /// was shown waits beside it.
    /// Whether it switched.
    fn switch_position(&mut self) -> bool {
        if self.correcting.is_some() || self.job.is_some() {
            self.status =
                "a correction is being preprocessed: switch position when it is done".into();
            return false;
        }
        let (s, o) = match (self.session.take(), self.other.take()) {
            (Some(s), Some(o)) => (s, o),
            // A study of one position stays open (it was dropped here, and the window
            // showed nothing).
            (s, o) => {
                (self.session, self.other) = (s, o);
                self.status = "the exam has one position open".into();
                return false;
            }
        };
        let from = crate::open::position_of(&s.study);
        let findings = std::mem::take(&mut self.findings);
        let (s, findings, o) = switch(s, findings, o);
        self.status = format!(
            "{}: at the place the camera was in {from}",
            crate::open::position_of(&s.study)
        );
        self.findings = findings;
        self.session = Some(s);
        self.other = Some(o);
        self.looked_up = None;
        std::mem::swap(&mut self.scout, &mut self.other_scout);
        self.boxes.reset();
        self.measure_from = None;
        self.polyp_span = None;
        self.slices.volume_changed();
        self.generation += 1;
        true
    }

    /// Switches to the other position at the place the link puts marker `label` there, and
    /// shows the place (the close-up box and the scout mark it).
    fn show_in_other(&mut self, label: &str) {
        let (Some(s), Some(o)) = (&self.session, &self.other) else {
            self.status = "the exam has one position open".into();
            return;
        };
        let Some(m) = self.findings.markers.iter().find(|m| m.label == label) else {
            // A marker of the other position: looked up here.
            if !self.show_other_marker_here(label) {
                self.status = format!("no marker {label} in either position");
            }
            return;
        };
        let Some(there) = o.place_of(s, m) else {
            self.status = format!("{label} lies near no part of the colon's centerline");
            return;
        };
        let from = crate::open::position_of(&s.study);
        let label = format!("{label} ({from})");
        if self.switch_position() {
            self.look_up(label, there);
        }
    }

    /// Looks at `x` in the position shown, where the link put the other position's marker
    /// `name`, and marks it there.
    fn look_up(&mut self, name: String, x: DVec3) {
        if let Some(s) = &mut self.session
            && look_at(s, x)
        {
            self.status = format!("{name}: where the link puts it here");
        }
        self.boxes.at = Some(x);
        self.looked_up = Some((name, x));
        self.slices.follow();
    }

    /// Looks at where the link puts the other position's marker `label` in the one shown;
    /// false when the other position has no such marker.
    fn show_other_marker_here(&mut self, label: &str) -> bool {
        let (Some(s), Some(o)) = (&self.session, &self.other) else {
            return false;
        };
        let Some(m) = o.findings.markers.iter().find(|m| m.label == label) else {
            return false;
        };
        let here = o.link.reversed().show_in(
            &o.session.study,
            &s.study,
            m.position + m.normal * voyage_core::OFF_WALL_MM,
        );
        let name = format!("{label} ({})", o.name());
        match here {
            Some(x) => self.look_up(name, x),
            None => self.status = format!("{name} lies near no part of the colon's centerline"),
        }
        true
    }

    fn go_to_marker(&mut self, label: &str) {
        let Some(m) = self.findings.markers.iter().find(|m| m.label == label) else {
            self.status = format!("no marker {label}");
            return;
        };
        let (view, position) = (m.view, m.position);
        if let Some(s) = &mut self.session {
            s.set_playing(false);
            s.place(view);
            self.boxes.at = Some(position);
            self.slices.follow();
            self.status = format!("back at {label}");
        }
    }

    /// A click on a slice at `x` (volume-local mm): to a viewing spot near it, the slices
    /// following; or why not, in the status line.
    fn move_to_point(&mut self, x: DVec3) {
        let Some(s) = &mut self.session else { return };
        match s.move_to_spot(x) {
            Ok(()) => {
                self.slices.follow();
                self.status = "moved to the point clicked".into();
            }
            Err(e) => self.status = e,
        }
    }
}
