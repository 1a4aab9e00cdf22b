//! The navigator window: a control strip on the left, the endoscopic view in the middle,
//! the scout on the right, the slices along the bottom (paper Fig. 8).

use std::{
    collections::BTreeMap,
    path::PathBuf,
    sync::{Arc, Mutex},
    time::Instant,
};

use egui::{Color32, Key, Modifiers, Pos2, Rect, RichText, Sense, Stroke, Vec2};
use glam::DVec3;
use serde_json::json;
use voyage_core::LEFT_OUT_DOUBT_ML;
use voyage_export::{PositionReading, ReportCoverage, export_pair_reading, export_reading};
use voyage_nav::{Camera, Direction};
use voyage_view::{
    CloseupBox, FindingKind, Findings, Hit, Material, MucosaMap, ReadingStep, TransferFunction,
    TranslucencyOptions, both_coverage, encode, pick, render_closeup, render_translucency,
};

use voyage_nav::Input;

use super::{
    WindowArgs,
    corrections::{self, Correction},
    coverage::WindowCoverage,
    endoscopy::{Endoscope, label, project, ray_at, surface_point_on_screen, visible_centerline},
    frame_times::FrameTimes,
    loader::{Job, Source},
    pixels::WindowGpu,
    positions::{Other, switch},
    report::{MarkerReport, PositionsReport, Report},
    scout::{ScoutClick, ScoutMarks, ScoutView},
    script::{Script, Step},
    session::Session,
    slices::{SliceAction, SlicePanel, SliceSource},
};
use crate::open::InputArgs;

/// What a click on the endoscopic view does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Tool {
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

/// What the window leaves behind for `voyage view` to report after it closes.
#[derive(Default)]
pub struct Outcome {
    pub errors: Vec<String>,
    pub report: Option<serde_json::Value>,
}

/// Input gathered for the submarine this frame.
#[derive(Default)]
struct Steering {
    /// Ray toward the point held (F_user).
    push: Option<DVec3>,
    /// Right-drag in points this frame (τ_option).
    look: Vec2,
}

/// An image shown over the view (the close-up volume rendering, the translucency view), and
/// the camera and box centre it was made for.
struct Closeup {
    texture: egui::TextureHandle,
    camera: Camera,
    center: DVec3,
}

/// The window's background, behind the unfilled panels.
const PANEL_BACKGROUND: Color32 = Color32::from_gray(27);

/// The panels' images among the window's [`voyage_render::PixelImages`].
const SLICE_IMAGES: [u64; 3] = [0, 1, 2];
const SCOUT_IMAGE: u64 = 3;
/// The other position's scout.
const OTHER_SCOUT_IMAGE: u64 = 4;
/// How long (simulated s) the window shows that the autopilot glided on after being stuck.
const RESCUE_NOTICE_S: f64 = 8.0;

/// What the user asks of the window, from a key, a control or a script: [`App::apply`]
/// carries it out, so the three cannot disagree.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Action {
    Quit,
    ExportFindings,
    ToggleHelp,
    /// Close the help, cancel a measurement.
    Cancel,
    Toggle(Switch),
    Set(Switch, bool),
    Tool(Tool),
    PlayPause,
    Reverse,
    Restart,
    NarrowerView,
    WiderView,
    /// A marker on the surface under the mouse cursor (in the view).
    MarkerUnderCursor,
    /// One end of a measurement on the surface under the mouse cursor (in the view).
    MeasureUnderCursor,
    /// Size the polyp under the mouse cursor and mark it.
    PolypUnderCursor,
    /// Rectum → cecum, cecum → rectum, then every unseen patch (issue 23).
    TwoWayReading,
    /// Fly to the largest unseen patch and outline it.
    NextUnseenPatch,
    /// Show the exam's other position at the same place (issue 39).
    SwitchPosition,
}

/// The window's on/off settings.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Switch {
    Centerline,
    Closeup,
    Translucency,
    Compass,
    Leveling,
    Still,
    /// Coverage marking of the frames shown.
    Coverage,
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
        bound: &[(NONE, Key::Space, Action::PlayPause)],
    },
    Binding {
        keys: "R",
        what: "reverse the direction (rectum / cecum)",
        bound: &[(NONE, Key::R, Action::Reverse)],
    },
    Binding {
        keys: "Home",
        what: "back to the start of the flight",
        bound: &[(NONE, Key::Home, Action::Restart)],
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
        bound: &[(NONE, Key::M, Action::MarkerUnderCursor)],
    },
    Binding {
        keys: "P",
        what: "polyp under the cursor: segment it, measure its largest diameter, mark it",
        bound: &[(NONE, Key::P, Action::PolypUnderCursor)],
    },
    Binding {
        keys: "D",
        what: "measure: press on two surface points",
        bound: &[(NONE, Key::D, Action::MeasureUnderCursor)],
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
            (NONE, Key::OpenBracket, Action::NarrowerView),
            (NONE, Key::CloseBracket, Action::WiderView),
        ],
    },
    Binding {
        keys: "Ctrl+E",
        what: "export the findings",
        bound: &[(CTRL, Key::E, Action::ExportFindings)],
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

pub struct App {
    args: WindowArgs,
    job: Option<Job>,
    session: Option<Session>,
    /// The exam's other position (supine and prone), waiting beside the one shown, and its
    /// scout (which shows where the camera's place lies in it).
    other: Option<Other>,
    other_scout: Option<ScoutView>,
    /// A marker of the other position looked up in the one shown: its label and place.
    looked_up: Option<(String, DVec3)>,
    /// What the open session was made from (its points are the corrections so far).
    source: Option<Source>,
    /// The job running is a correction of the open session, which stays in use meanwhile.
    correcting: Option<Correction>,
    /// Why the last correction failed (the session before it stays).
    correction_error: Option<String>,
    generation: u64,
    error: Option<String>,
    open_path: String,
    endoscope: Endoscope,
    scout: Option<ScoutView>,
    slices: SlicePanel,
    /// The window has a [`WindowGpu`] (its wgpu renderer draws the panels' images).
    pixels_gpu: bool,
    findings: Findings,
    tool: Tool,
    /// The kind a new marker gets.
    marker_kind: FindingKind,
    /// The last polyp sized: the two surface points its diameter spans (drawn in the view).
    polyp_span: Option<[DVec3; 2]>,
    measure_from: Option<DVec3>,
    note: String,
    export_dir: String,
    show_help: bool,
    show_centerline: bool,
    closeup_on: bool,
    closeup: Option<Closeup>,
    /// Marker whose neighbourhood the close-up shows (instead of the view centre).
    closeup_at: Option<DVec3>,
    translucency_on: bool,
    translucency: Option<Closeup>,
    status: String,
    times: FrameTimes,
    /// Frames drawn since the study became ready (or failed).
    frames: u64,
    view_rect: Option<Rect>,
    last_cells: Vec<u32>,
    script: Option<Script>,
    steer_script: Option<([f32; 2], u32)>,
    look_script: Option<(Vec2, u32)>,
    recorded: BTreeMap<String, [f64; 7]>,
    screenshot_pending: bool,
    announced: bool,
    outcome: Arc<Mutex<Outcome>>,
    quitting: bool,
}

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
    pub fn new(
        cc: &eframe::CreationContext<'_>,
        source: Option<Source>,
        args: WindowArgs,
        outcome: Arc<Mutex<Outcome>>,
    ) -> Self {
        // Panels are not filled: the frame is cleared to the panel colour instead. On a CPU
        // Vulkan driver every shaded pixel costs, and filling the panels would shade the
        // whole window once more each frame.
        let mut visuals = egui::Visuals::dark();
        visuals.panel_fill = Color32::TRANSPARENT;
        cc.egui_ctx.set_visuals(visuals);
        // The view and the panels' images are drawn by the window's own renderer where it is
        // wgpu.
        if let Some(rs) = &cc.wgpu_render_state {
            WindowGpu::install(rs);
        }
        let pixels_gpu = cc.wgpu_render_state.is_some();
        let endoscope = Endoscope::new(cc.wgpu_render_state.as_ref(), args.cpu);
        let script = match args.script.as_deref().map(Script::load).transpose() {
            Ok(s) => s,
            Err(e) => {
                note_error(&outcome, format!("{e:#}"));
                None
            }
        };
        let job = source.map(|s| Job::start(s, cc.egui_ctx.clone()));
        App {
            args,
            job,
            session: None,
            source: None,
            correcting: None,
            correction_error: None,
            generation: 0,
            other: None,
            other_scout: None,
            looked_up: None,
            error: None,
            open_path: String::new(),
            endoscope,
            scout: None,
            slices: SlicePanel::new(SLICE_IMAGES, pixels_gpu),
            pixels_gpu,
            findings: Findings::default(),
            tool: Tool::Steer,
            marker_kind: FindingKind::Other,
            polyp_span: None,
            measure_from: None,
            note: String::new(),
            export_dir: "findings".into(),
            show_help: false,
            show_centerline: true,
            closeup_on: false,
            closeup: None,
            closeup_at: None,
            translucency_on: false,
            translucency: None,
            status: String::new(),
            times: FrameTimes::default(),
            frames: 0,
            view_rect: None,
            last_cells: Vec::new(),
            script,
            steer_script: None,
            look_script: None,
            recorded: BTreeMap::new(),
            screenshot_pending: false,
            announced: false,
            outcome,
            quitting: false,
        }
    }

    fn open(&mut self, source: Source, ctx: &egui::Context) {
        self.error = None;
        self.correcting = None;
        self.status = format!("opening {}", source.describe());
        self.job = Some(Job::start(source, ctx.clone()));
    }

    /// Preprocesses the open study again with a correction, in the background; the session
    /// open stays in use until the new one is ready.
    fn correct(&mut self, c: Correction, ctx: &egui::Context) {
        let (Some(s), Some(source)) = (&self.session, &self.source) else {
            return;
        };
        if self.job.is_some() {
            self.status = "a correction is still being preprocessed".into();
            return;
        }
        if matches!(source, Source::Phantom { pair: true, .. }) {
            self.status = "the phantom pair is made afresh each time: corrections are for a scan's files (voyage phantom colon --pair --dicom DIR writes them)".into();
            return;
        }
        // The points of the position shown: with two positions open, the correction is of
        // that one alone.
        let points = c.applied_to(&s.points, s.study.storage.input_geometry());
        self.status = format!("preprocessing again: {}", c.describe());
        self.correction_error = None;
        self.correcting = Some(c);
        let source = match self.other.is_some() {
            true => source.with_series(s.series_uid.clone()),
            false => source.clone(),
        };
        self.job = Some(Job::start(source.with_points(points), ctx.clone()));
    }

    fn poll_job(&mut self) {
        let Some(job) = &mut self.job else { return };
        let Some(result) = job.poll() else { return };
        let seconds = job.started.elapsed().as_secs_f64();
        let source = job.source.clone();
        self.job = None;
        if let Some(c) = self.correcting.take() {
            let one = result.and_then(|v| {
                v.into_iter()
                    .next()
                    .ok_or_else(|| anyhow::anyhow!("nothing was opened"))
            });
            self.corrected(c, source, one, seconds);
            return;
        }
        let result = result.and_then(|v| {
            let mut v = v.into_iter();
            let first = v
                .next()
                .ok_or_else(|| anyhow::anyhow!("nothing was opened"))?;
            Ok((first, v.next()))
        });
        match result {
            Ok((mut s, second)) => {
                s.set_playing(!self.args.paused);
                self.status = format!(
                    "{} ready in {:.1} s: centerline {:.0} mm, {} triangles in {} cells",
                    s.exam.name,
                    seconds,
                    s.study.centerline.length_mm,
                    s.mesh.triangles.len(),
                    s.mesh.cells()
                );
                self.scout = Some(ScoutView::new(
                    s.study.ct.geometry(),
                    PANEL_BACKGROUND,
                    SCOUT_IMAGE,
                    self.pixels_gpu,
                ));
                self.slices = SlicePanel::new(SLICE_IMAGES, self.pixels_gpu);
                if s.study.segmentation.from_mask {
                    // A mask holds 0 and 1: show it as two greys, not as HU.
                    (self.slices.window, self.slices.level) = (2.0, 0.5);
                }
                self.findings = Findings::default();
                self.looked_up = None;
                self.polyp_span = None;
                self.closeup = None;
                self.translucency = None;
                self.closeup_at = None;
                self.measure_from = None;
                self.other = second.map(|o| Other::new(&s, o, Findings::default()));
                self.other_scout = self.other.as_ref().map(|o| {
                    ScoutView::new(
                        o.session.study.ct.geometry(),
                        PANEL_BACKGROUND,
                        OTHER_SCOUT_IMAGE,
                        self.pixels_gpu,
                    )
                });
                if let Some(o) = &self.other {
                    self.status += &format!(
                        "; {} open beside it (O switches to the same place there)",
                        o.name()
                    );
                }
                self.session = Some(s);
                self.source = Some(source);
                self.correction_error = None;
                self.generation += 1;
                self.frames = 0;
                // Frame statistics are of frames drawn with a study, not of the loading.
                self.times = FrameTimes::default();
                self.announced = false;
            }
            Err(e) => {
                let msg = format!("{e:#}");
                self.error = Some(msg.clone());
                self.status = "could not open the study".into();
                self.frames = 0;
                note_error(&self.outcome, msg);
            }
        }
    }

    /// A correction's run is done: its session replaces the open one (findings, window and
    /// level kept: the CT is the same), or the error is shown and the open one stays.
    fn corrected(
        &mut self,
        c: Correction,
        source: Source,
        result: anyhow::Result<Session>,
        seconds: f64,
    ) {
        match result {
            Ok(mut s) => {
                let was = self
                    .session
                    .as_ref()
                    .map_or(0.0, |o| o.study.centerline.length_mm);
                s.set_playing(false);
                let kept = s
                    .study
                    .segmentation
                    .segments
                    .iter()
                    .filter(|x| x.kept)
                    .count();
                self.status = format!(
                    "{} in {seconds:.1} s: {kept} colon segment{}, centerline {:.0} mm (was {was:.0})",
                    c.describe(),
                    if kept == 1 { "" } else { "s" },
                    s.study.centerline.length_mm
                );
                self.closeup = None;
                self.translucency = None;
                self.measure_from = None;
                self.slices.follow();
                if let Some(v) = &mut self.scout {
                    v.colon_changed();
                }
                if let Some(o) = self.other.take() {
                    // The exam's name, with its position, and the exam as the source: the
                    // other position's corrections are its own.
                    if let Some(old) = &self.session {
                        s.exam.name = old.exam.name.clone();
                    }
                    self.other = Some(Other::new(&s, o.session, o.findings));
                } else {
                    self.source = Some(source);
                }
                self.session = Some(s);
                self.generation += 1;
            }
            Err(e) => {
                let msg = format!("{e:#}");
                self.status = format!("{}: not possible", c.describe());
                self.correction_error = Some(msg);
            }
        }
    }

    /// Keyboard shortcuts from [`KEYMAP`] (not while a text field has the keyboard).
    fn shortcuts(&mut self, ctx: &egui::Context) {
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        for binding in KEYMAP {
            for &(modifiers, key, action) in binding.bound {
                if ctx.input_mut(|i| i.consume_key(modifiers, key)) {
                    self.apply(action, ctx);
                }
            }
        }
    }

    /// Carries out what a key, a control or a script asked. Actions on the flight wait for
    /// a study; the ones under the cursor need the cursor in the view.
    fn apply(&mut self, action: Action, ctx: &egui::Context) {
        let cursor = ctx
            .input(|i| i.pointer.hover_pos())
            .filter(|p| self.view_rect.is_some_and(|r| r.contains(*p)));
        match action {
            Action::Quit => self.quit(ctx),
            Action::ExportFindings => self.export(PathBuf::from(self.export_dir.clone())),
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
            Action::MarkerUnderCursor => {
                if let Some(p) = cursor {
                    self.drop_marker(p);
                }
            }
            Action::MeasureUnderCursor => {
                if let Some(p) = cursor {
                    self.measure_point(p);
                }
            }
            Action::PolypUnderCursor => {
                if let Some(p) = cursor {
                    self.size_polyp(p);
                }
            }
            Action::PlayPause => {
                if let Some(s) = &mut self.session {
                    s.set_playing(!s.playing);
                }
            }
            Action::SwitchPosition => {
                self.switch_position();
            }
            Action::Reverse => {
                if let Some(s) = &mut self.session {
                    s.set_direction(s.direction().reversed());
                }
            }
            Action::Restart => {
                if let Some(s) = &mut self.session {
                    s.restart();
                }
            }
            Action::NarrowerView => {
                if let Some(s) = &mut self.session {
                    s.fov = (s.fov - 5.0).max(30.0);
                }
            }
            Action::WiderView => {
                if let Some(s) = &mut self.session {
                    s.fov = (s.fov + 5.0).min(Camera::MAX_FOV_DEG);
                }
            }
            Action::TwoWayReading => {
                if let Some(s) = &mut self.session {
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
            }
            Action::NextUnseenPatch => self.next_unseen_patch(),
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
    fn switch(&mut self, switch: Switch) -> Option<&mut bool> {
        Some(match switch {
            Switch::Centerline => &mut self.show_centerline,
            Switch::Closeup => &mut self.closeup_on,
            Switch::Translucency => &mut self.translucency_on,
            Switch::Compass => &mut self.session.as_mut()?.sub.modes.compass,
            Switch::Leveling => &mut self.session.as_mut()?.sub.modes.leveling,
            Switch::Still => &mut self.session.as_mut()?.sub.modes.still,
            Switch::Coverage => &mut self.session.as_mut()?.coverage.on,
        })
    }

    fn quit(&mut self, ctx: &egui::Context) {
        self.quitting = true;
        ctx.send_viewport_cmd(egui::ViewportCommand::Close);
    }

    /// The surface point under a point of the view (searching the cells last drawn first).
    fn pick(&self, at: Pos2) -> Option<Hit> {
        let (s, rect) = (self.session.as_ref()?, self.view_rect?);
        let cam = s.camera();
        let ray = ray_at(&cam, rect, at);
        pick(&s.mesh, Some(&self.last_cells), cam.pose.position, ray)
            .or_else(|| pick(&s.mesh, None, cam.pose.position, ray))
    }

    fn drop_marker(&mut self, at: Pos2) {
        let Some(hit) = self.pick(at) else {
            self.status = "no surface under the cursor".into();
            return;
        };
        let Some(s) = &self.session else { return };
        let note = std::mem::take(&mut self.note);
        let label = self
            .findings
            .add_marker(hit.point, hit.normal, s.pose(), note)
            .label
            .clone();
        if let Some(m) = self.findings.marker_mut(&label) {
            m.kind = self.marker_kind;
        }
        self.status = format!("marker {label} at {:.1} mm from the camera", hit.distance);
    }

    /// Segments the polyp under `at`, measures its largest diameter and marks it as a polyp
    /// of that size; says so when nothing stands out of the wall there.
    fn size_polyp(&mut self, at: Pos2) {
        let Some(hit) = self.pick(at) else {
            self.status = "no surface under the cursor".into();
            return;
        };
        let Some(s) = &self.session else { return };
        let Some(size) = voyage_view::measure_polyp(&s.mesh, hit.point, hit.normal) else {
            self.status = "no polyp there: nothing stands out of the wall under the cursor (or it is over 4 cm)".into();
            return;
        };
        let note = std::mem::take(&mut self.note);
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

    fn run_script(&mut self, ctx: &egui::Context) {
        // A correction being preprocessed holds the script: the next step sees its result.
        if self.session.is_none() || self.job.is_some() {
            return;
        }
        // A two-way reading holds the script until it is done.
        if self
            .session
            .as_ref()
            .is_some_and(|s| s.coverage.reading_running())
        {
            return;
        }
        let Some(script) = &mut self.script else {
            return;
        };
        let Some(step) = script.next_step() else {
            return;
        };
        match step {
            Step::Wait(n) => script.busy = n,
            Step::Steer { at, frames } => {
                self.steer_script = Some((at, frames));
                script.busy = frames;
            }
            Step::Look { dx, dy, frames } => {
                self.look_script = Some((Vec2::new(dx, dy), frames));
                script.busy = frames;
            }
            Step::Play(on) => {
                if let Some(s) = &mut self.session {
                    s.set_playing(on);
                }
            }
            Step::Direction(d) => {
                if let Some(s) = &mut self.session {
                    s.set_direction(if d == "backward" {
                        Direction::Backward
                    } else {
                        Direction::Forward
                    });
                }
            }
            Step::Marker { at, note, kind } => {
                self.note = note;
                let before = std::mem::replace(&mut self.marker_kind, kind);
                if let Some(p) = self.view_point(at) {
                    self.drop_marker(p);
                }
                self.marker_kind = before;
            }
            Step::Polyp { at, note } => {
                self.note = note;
                if let Some(p) = self.view_point(at) {
                    self.size_polyp(p);
                }
            }
            Step::Measure { from, to } => {
                if let (Some(a), Some(b)) = (self.view_point(from), self.view_point(to)) {
                    self.measure_from = None;
                    self.measure_point(a);
                    self.measure_point(b);
                }
            }
            Step::Jump(f) => {
                if let Some(s) = &mut self.session {
                    let n = s.study.centerline.points_mm.len();
                    let i = (f.clamp(0.0, 1.0) * n.saturating_sub(1) as f64).round() as usize;
                    if let Err(e) = s.jump_to_centerline(i) {
                        self.status = e;
                    }
                    self.slices.follow();
                }
            }
            Step::MoveTo(lps) => {
                if let Some(s) = &mut self.session {
                    let x = s
                        .study
                        .ct
                        .geometry()
                        .patient_to_local(DVec3::from_array(lps));
                    s.set_playing(false);
                    self.move_to_point(x);
                }
            }
            Step::GoTo(label) => self.go_to_marker(&label),
            Step::SwitchPosition(on) => {
                if on {
                    self.switch_position();
                }
            }
            Step::ShowInOther(label) => self.show_in_other(&label),
            Step::Pose(a) => {
                if let (Some(s), Some(p)) = (&mut self.session, voyage_nav::Pose::from_array(a)) {
                    if s.sub.is_safe(&s.field, p.position) {
                        s.set_playing(false);
                        s.place(p);
                        self.slices.follow();
                    } else {
                        self.status = "the scripted pose is not inside the colon".into();
                    }
                }
            }
            Step::TwoWay(on) => {
                if on {
                    self.apply(Action::TwoWayReading, ctx);
                }
            }
            Step::NextUnseen(on) => {
                if on {
                    self.apply(Action::NextUnseenPatch, ctx);
                }
            }
            Step::Coverage(on) => self.apply(Action::Set(Switch::Coverage, on), ctx),
            Step::Closeup(on) => self.apply(Action::Set(Switch::Closeup, on), ctx),
            Step::Translucency(on) => self.apply(Action::Set(Switch::Translucency, on), ctx),
            Step::Centerline(on) => self.apply(Action::Set(Switch::Centerline, on), ctx),
            Step::SlicesCleansed(on) => self.slices.cleansed = on,
            Step::SlicesOutline(on) => self.slices.outline = on,
            Step::Record(name) => {
                if let Some(s) = &self.session {
                    self.recorded.insert(name, s.pose().to_array());
                }
            }
            Step::Screenshot(path) => {
                self.screenshot(ctx, path, false);
                // The picture is of a frame still to come: let it come before the next step.
                if let Some(script) = &mut self.script {
                    script.busy = 2;
                }
            }
            Step::Export(dir) => self.export(dir),
            Step::Correct(c) => self.correct(c, ctx),
            Step::Quit(now) => {
                if now {
                    self.quit(ctx);
                }
            }
        }
    }

    /// A point of the view given as fractions of its size.
    fn view_point(&self, f: [f32; 2]) -> Option<Pos2> {
        self.view_rect
            .map(|r| r.min + Vec2::new(f[0], f[1]) * r.size())
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
        let (Some(s), Some(o)) = (self.session.take(), self.other.take()) else {
            self.status = "the exam has one position open".into();
            return false;
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
        self.closeup = None;
        self.translucency = None;
        self.closeup_at = None;
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
            && super::positions::look_at(s, x)
        {
            self.status = format!("{name}: where the link puts it here");
        }
        self.closeup_at = Some(x);
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
            self.closeup_at = Some(position);
            self.slices.follow();
            self.status = format!("back at {label}");
        }
    }

    /// Saves a PNG of the whole window (the next frame's pixels); with `then_quit` the
    /// window closes once it is written.
    fn screenshot(&mut self, ctx: &egui::Context, path: PathBuf, then_quit: bool) {
        let outcome = self.outcome.clone();
        let ctx2 = ctx.clone();
        self.screenshot_pending = then_quit;
        ctx.send_viewport_cmd(egui::ViewportCommand::Screenshot(
            egui::ScreenshotCallback::new(move |image| {
                let (w, h) = (image.size[0] as u32, image.size[1] as u32);
                let rgba: Vec<u8> = image.pixels.iter().flat_map(|c| c.to_array()).collect();
                if let Err(e) = voyage_io::write_png(&path, &rgba, w, h) {
                    note_error(&outcome, format!("{}: {e:#}", path.display()));
                }
                if then_quit {
                    ctx2.send_viewport_cmd(egui::ViewportCommand::Close);
                }
                ctx2.request_repaint();
            }),
        ));
    }

    fn write_report(&mut self) {
        let report = serde_json::to_value(self.report()).expect("a report is plain data");
        if let Ok(mut o) = self.outcome.lock() {
            o.report = Some(report);
        }
    }

    fn report(&self) -> Report {
        let s = self.session.as_ref();
        Report {
            ready: s.is_some(),
            error: self.error.clone(),
            frames: self.frames,
            renderer: self.endoscope.renderer_name.clone(),
            pose: s.map(|s| s.pose().to_array()),
            playing: s.map(|s| s.playing),
            recorded: self.recorded.clone(),
            markers: self.findings.markers.iter().map(MarkerReport::of).collect(),
            measurements_mm: self
                .findings
                .measurements
                .iter()
                .map(|m| m.length_mm())
                .collect(),
            frame_ms: self.times.summary(),
            flying_frame_ms: self.times.flying(),
            render_ms: self.times.mean_render_ms(),
            view_rect: self
                .view_rect
                .map(|r| [r.left(), r.top(), r.right(), r.bottom()]),
            cells: self.endoscope.stats.cells,
            triangles: self.endoscope.stats.triangles,
            colon: s.map(|s| colon_report(s, self.source.as_ref())),
            slice_letters: self.slices.letters_drawn.clone(),
            scout_hovered: self.scout.as_ref().and_then(|v| v.hovered),
            coverage: s.map(|s| s.coverage.report()),
            correction_error: self.correction_error.clone(),
            positions: s.zip(self.other.as_ref()).map(|(s, o)| PositionsReport {
                shown: crate::open::position_of(&s.study),
                other: o.name(),
                linked_mm: o.linked.map(|p| p.to_array()),
                looked_up: self
                    .looked_up
                    .as_ref()
                    .map(|(l, p)| (l.clone(), p.to_array())),
                other_markers: o.findings.markers.iter().map(MarkerReport::of).collect(),
            }),
            status: self.status.clone(),
        }
    }

    fn top_bar(&mut self, ui: &mut egui::Ui) {
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
                    let path = PathBuf::from(self.open_path.trim());
                    self.open(
                        Source::File(InputArgs {
                            input: path,
                            mask: false,
                            series: None,
                            points: Default::default(),
                        }),
                        ui.ctx(),
                    );
                }
                if ui.button("Demo phantom").clicked() {
                    self.open(
                        Source::Phantom {
                            small: false,
                            pair: false,
                            points: Default::default(),
                        },
                        ui.ctx(),
                    );
                }
                ui.separator();
                if ui.button("Help (H)").clicked() {
                    self.apply(Action::ToggleHelp, &ui.ctx().clone());
                }
                ui.label(RichText::new(&self.status).color(Color32::from_gray(170)));
            });
        });
    }

    fn controls(&mut self, ui: &mut egui::Ui) {
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
                actions.push(Action::PlayPause);
            }
            if ui.button("Start over").on_hover_text("Home").clicked() {
                actions.push(Action::Restart);
            }
        });
        let mut dir = s.direction();
        ui.radio_value(&mut dir, Direction::Forward, "rectum to cecum");
        ui.radio_value(&mut dir, Direction::Backward, "cecum to rectum");
        s.set_direction(dir);
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
                    "no progress for {:.0} s at {:.0} mm along the colon: gliding on along the centerline",
                    voyage_nav::STUCK_S,
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
        if let Some(c) = asked {
            self.correct(c, ui.ctx());
        }
        let Some(s) = &mut self.session else { return };
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
        let mut go = None;
        let mut show_in_other = None;
        let mut remove_marker = None;
        for (i, m) in self.findings.markers.iter().enumerate() {
            ui.horizontal(|ui| {
                if ui
                    .button(&m.label)
                    .on_hover_text("fly back to this marker")
                    .clicked()
                {
                    go = Some(m.label.clone());
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
                    show_in_other = Some(m.label.clone());
                }
                if ui.small_button("x").clicked() {
                    remove_marker = Some(i);
                }
            });
        }
        let mut show_here = None;
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
                        show_here = Some(m.label.clone());
                    }
                });
            }
        }
        let mut remove_measure = None;
        for (i, m) in self.findings.measurements.iter().enumerate() {
            ui.horizontal(|ui| {
                ui.label(format!("{}: {:.1} mm", m.label, m.length_mm()));
                if ui.small_button("x").clicked() {
                    remove_measure = Some(i);
                }
            });
        }
        if let Some(i) = remove_marker {
            self.findings.markers.remove(i);
        }
        if let Some(i) = remove_measure {
            self.findings.measurements.remove(i);
        }
        if let Some(l) = go {
            self.go_to_marker(&l);
        }
        if let Some(l) = show_in_other {
            self.show_in_other(&l);
        }
        if let Some(l) = show_here {
            self.show_other_marker_here(&l);
        }
        ui.horizontal(|ui| {
            ui.add(egui::TextEdit::singleline(&mut self.export_dir).desired_width(120.0));
            if ui
                .button("Export")
                .on_hover_text("Ctrl+E: findings.json, Slicer .mrk.json and a PNG per marker")
                .clicked()
            {
                actions.push(Action::ExportFindings);
            }
        });
        let ctx = ui.ctx().clone();
        for action in actions {
            self.apply(action, &ctx);
        }
    }

    fn scout_panel(&mut self, ui: &mut egui::Ui) {
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
                    Some(ScoutClick::Centerline(i)) => match s.jump_to_centerline(i) {
                        Ok(()) => {
                            self.slices.follow();
                            self.status = format!(
                                "jumped to {:.0} mm along the centerline",
                                s.study.centerline.arc_mm.get(i).copied().unwrap_or(0.0)
                            );
                        }
                        Err(e) => self.status = e,
                    },
                    None => {}
                }
            });
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

    fn slice_panel(&mut self, ui: &mut egui::Ui) {
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
                    Some(SliceAction::MoveTo(p)) => self.move_to_point(p),
                    Some(SliceAction::Correct(c)) => self.correct(c, ui.ctx()),
                    None => {}
                }
            });
    }

    fn endoscopy_panel(&mut self, ui: &mut egui::Ui, frame: &eframe::Frame, dt: f64) {
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
            match self.tool {
                Tool::Marker => self.drop_marker(p),
                Tool::Measure => self.measure_point(p),
                Tool::Polyp => self.size_polyp(p),
                Tool::Steer => {}
            }
        }
        out
    }

    /// Where a box over the view is drawn from: the camera, and the marker flown back to or
    /// the surface point at the view's centre.
    fn overlay_target(&self, rect: Rect) -> Option<(Camera, DVec3)> {
        let s = self.session.as_ref()?;
        let center = match self.closeup_at {
            Some(c) => c,
            None => self.pick(rect.center())?.point,
        };
        Some((s.camera(), center))
    }

    /// The close-up volume rendering over the view: the CT ray-cast in a small box around
    /// the marker flown back to, or around the surface point at the view's centre.
    fn closeup_overlay(&mut self, ui: &egui::Ui, rect: Rect) {
        if !self.closeup_on {
            self.closeup = None;
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
            &mut self.closeup,
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
    fn translucency_overlay(&mut self, ui: &egui::Ui, rect: Rect) {
        if !self.translucency_on {
            self.translucency = None;
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
            &mut self.translucency,
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
    fn overlays(&mut self, ui: &egui::Ui, rect: Rect) {
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
            let text = if gap.at_edge {
                format!(
                    "the colon leaves the scan here: {:.0} mm joined inside it, the flight keeps to the path",
                    gap.length_mm
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

    /// The view while nothing is open yet: progress, or the error and what to do.
    fn waiting(&mut self, ui: &mut egui::Ui) {
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

    fn help(&mut self, ctx: &egui::Context) {
        let mut open = self.show_help;
        egui::Window::new("Keys and mouse")
            .open(&mut open)
            .collapsible(false)
            .resizable(false)
            .anchor(egui::Align2::CENTER_CENTER, Vec2::ZERO)
            .show(ctx, |ui| {
                egui::Grid::new("keys").striped(true).show(ui, |ui| {
                    for binding in KEYMAP {
                        ui.label(RichText::new(binding.keys).strong());
                        ui.label(binding.what);
                        ui.end_row();
                    }
                });
            });
        self.show_help &= open;
    }

    /// Once per study: a line on stdout saying where the view is (in window pixels), for
    /// tools that drive the window from outside (tests with xdotool).
    fn announce(&mut self, ctx: &egui::Context) {
        if self.announced || self.session.is_none() || self.frames < 2 {
            return;
        }
        let Some(r) = self.view_rect else { return };
        let ppp = ctx.pixels_per_point();
        // The scout's centerline middle, for a tool that clicks it.
        let probe = self
            .scout
            .as_ref()
            .and_then(|v| v.probe)
            .map(|ps| ps.map(|p| [p.x * ppp, p.y * ppp]));
        println!(
            "{}",
            json!({"ready": true, "view_px": [r.left() * ppp, r.top() * ppp, r.right() * ppp, r.bottom() * ppp], "scout_centerline_px": probe})
        );
        use std::io::Write;
        let _ = std::io::stdout().flush();
        self.announced = true;
    }
}

/// Keeps an error for `voyage view` to report once the window has closed.
fn note_error(outcome: &Mutex<Outcome>, msg: String) {
    if let Ok(mut o) = outcome.lock() {
        o.errors.push(msg);
    }
}

impl eframe::App for App {
    fn ui(&mut self, ui: &mut egui::Ui, frame: &mut eframe::Frame) {
        let ctx = ui.ctx().clone();
        let now = Instant::now();
        // Scripted runs step the physics by a fixed 1/30 s per frame while the script runs, so
        // that they do the same on every machine; interactive use, and a window whose script
        // is done, follows the clock (a mouse held for 0.6 s turns the view as far at 30 as at
        // 100 frames/s).
        let scripted = self.script.as_ref().is_some_and(|s| !s.finished());
        let flying = self.session.as_ref().is_some_and(|s| s.playing);
        let since = self.times.tick(now, flying);
        let dt = match (since, scripted || self.args.screenshot.is_some()) {
            (Some(s), false) => s,
            _ => 1.0 / 30.0,
        };

        self.poll_job();
        self.shortcuts(&ctx);
        self.run_script(&ctx);
        let title = match &self.session {
            Some(s) => format!("voyage — {}", s.exam.name),
            None => "voyage".into(),
        };
        ctx.send_viewport_cmd(egui::ViewportCommand::Title(title));

        self.top_bar(ui);
        self.controls(ui);
        self.slice_panel(ui);
        self.scout_panel(ui);
        self.endoscopy_panel(ui, frame, dt);
        self.help(&ctx);

        if self.job.is_none() {
            self.frames += 1;
        }
        self.announce(&ctx);
        if let Some(path) = self.args.screenshot.clone()
            && !self.screenshot_pending
            && self.frames >= self.args.after_frames
            && self.script.as_ref().is_none_or(Script::finished)
        {
            self.screenshot(&ctx, path, true);
        }
        if !self.quitting {
            ctx.request_repaint();
        }
    }

    fn clear_color(&self, _visuals: &egui::Visuals) -> [f32; 4] {
        PANEL_BACKGROUND.to_normalized_gamma_f32()
    }

    fn on_exit(&mut self) {
        self.write_report();
    }
}

/// The colon's segments, bridged gaps, the patient's position and the warnings, as
/// preprocessing reported them. Each segment has a box to take it in or leave it out; the
/// correction asked for, if any, is returned (`busy`: one is being preprocessed).
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

/// The colon as the report gives it: segments kept or not, the centerline, the
/// corrections in force (LPS mm, or the frame the user chose with --coords).
fn colon_report(s: &Session, source: Option<&Source>) -> serde_json::Value {
    let seg = &s.study.segmentation;
    let cl = &s.study.centerline;
    let g = s.study.ct.geometry();
    let lps = |i: usize| {
        cl.points_mm
            .get(i)
            .map(|&p| g.local_to_patient(DVec3::from_array(p)).to_array())
    };
    let points = source.map(|x| x.points().clone()).unwrap_or_default();
    let arr = |v: &[DVec3]| v.iter().map(|p| p.to_array()).collect::<Vec<_>>();
    json!({
        "segments": seg.segments.iter().map(|x| json!({"label": x.label, "order": x.order, "kept": x.kept, "gas_ml": x.gas_ml, "anchor_lps_mm": x.anchor_lps_mm, "reason": x.reason})).collect::<Vec<_>>(),
        "gaps": seg.gaps.len(),
        "warnings": seg.warnings,
        "position": seg.orientation.position.code(),
        "centerline_mm": cl.length_mm,
        "start_lps_mm": lps(0),
        "end_lps_mm": lps(cl.points_mm.len().saturating_sub(1)),
        "corrections": {"seed": arr(&points.seed), "exclude": arr(&points.exclude), "source": points.source.map(|p| p.to_array()), "target": points.target.map(|p| p.to_array())},
    })
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
