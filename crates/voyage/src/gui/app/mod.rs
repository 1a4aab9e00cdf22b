//! The navigator window: a control strip on the left, the endoscopic view in the middle,
//! the scout on the right, the slices along the bottom (paper Fig. 8).
//!
//! - `mod.rs`: the [`App`], its study opened and corrected in the background, the frame's
//!   order of work, the report on closing;
//! - `actions.rs`: what the user asks, from keys, controls and scripts, and carrying it out;
//! - `script.rs`: scripted runs (`voyage view --script`), step by step through the actions;
//! - `controls.rs`: the top bar and the control strip;
//! - `panels.rs`: the scout, the slices and the endoscopic view with its mouse;
//! - `overlays.rs`: what is drawn over the view.

mod actions;
mod controls;
mod overlays;
mod panels;
mod script;

use std::{
    collections::BTreeMap,
    path::PathBuf,
    sync::{Arc, Mutex},
    time::Instant,
};

use egui::{Color32, Rect, Vec2};
use glam::DVec3;
use serde_json::json;
use voyage_view::{FindingKind, Findings};

use actions::Tool;
use overlays::BoxViews;
pub use script::Script;

use super::{
    WindowArgs,
    corrections::Correction,
    endoscopy::Endoscope,
    frame_times::FrameTimes,
    loader::{Job, Source},
    pixels::WindowGpu,
    positions::Other,
    report::{MarkerReport, PositionsReport, Report},
    scout::ScoutView,
    session::Session,
    slices::SlicePanel,
};

/// What the window leaves behind for `voyage view` to report after it closes.
#[derive(Default)]
pub struct Outcome {
    pub errors: Vec<String>,
    pub report: Option<serde_json::Value>,
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
    /// The close-up and translucency views over the endoscopic view.
    boxes: BoxViews,
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

impl App {
    pub fn new(
        cc: &eframe::CreationContext<'_>,
        source: Option<Source>,
        args: WindowArgs,
        script: Option<Script>,
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
            boxes: BoxViews::default(),
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
                self.boxes.reset();
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
                // The CT is the same: a marker's place shown stays.
                self.boxes.images_stale();
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
