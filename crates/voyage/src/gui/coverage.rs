//! Coverage in the window: the frames shown mark the mucosa they show, on a small CPU frame
//! of the same view (exact culling, [`voyage_view::Reader`]), so that it costs the same on
//! any renderer and never reads a GPU buffer back. Marking is held to [`BUDGET_SHARE`] of the
//! window's frame time: where a frame is cheap to mark every frame is, else every k-th
//! (consecutive frames of a flight differ by a fraction of a millimetre), and a camera that
//! stands still is marked once. The session's coverage counts every frame since the study
//! opened; the flight's, the frames since the direction was last set.
//! The two-way reading (rectum → cecum, cecum → rectum, then a review of every unseen
//! patch) is `voyage_view`'s [`ReadingRun`], the one `voyage coverage` and `voyage report`
//! run: the window steps it once per frame and shows each move, holding a glance for
//! [`GLANCE_FRAMES`] and a review's visit for [`DWELL_FRAMES`].

use std::time::Instant;

use glam::DVec3;
use voyage_core::{Cells, Study};
use voyage_nav::{BrickStore, Camera, Pose};
use voyage_view::{
    CellMesh, Coverage, CoverageOptions, Lumen, Patch, READING_FOV_DEG, Reader, ReadingMove,
    ReadingRun, ReadingStep, Scene, ScoutMesh, patch_pose,
};

use super::report::{CoverageReport, ReadingReport};

/// The share of the window's frame time marking may take.
pub const BUDGET_SHARE: f64 = 0.08;

/// Height (pixels) of the frame coverage is marked on; its width follows the view's aspect.
pub const MARK_HEIGHT: u32 = 128;

/// Patches "next unseen" tries for a viewpoint, largest first.
const NEXT_TRIES: usize = 10;

/// Frames the window holds a review's visit on screen (the reading marked it once).
pub const DWELL_FRAMES: u32 = 20;

/// Frames the window holds a glance of the reading's flights on screen.
pub const GLANCE_FRAMES: u32 = 8;

pub struct WindowCoverage {
    /// Marking is on (a switch, so its cost can be measured against none).
    pub on: bool,
    reader: Reader,
    /// Everything shown since the study opened.
    pub session: Coverage,
    /// What the current flight (direction) has shown.
    pub flight: Coverage,
    /// The two-way reading, while it runs and after.
    pub reading: Option<ReadingRun>,
    /// Frames the reading's last move stays on screen before the next step.
    hold: u32,
    /// The patch last visited, outlined in the view: its boundary edges.
    pub outline: Vec<[DVec3; 2]>,
    last: Option<(Pose, f64, [u32; 2])>,
    mark_ms: Vec<f64>,
    /// Marking time the frames so far have allowed and not used (ms).
    budget_ms: f64,
    /// Running mean time of one step of the reading (ms).
    step_ms: f64,
    /// Frames that asked to be marked, and those that were.
    pub frames_asked: u64,
    pub frames_marked: u64,
    /// The scout's colouring: unseen share per scout vertex, its version, and the session's
    /// coverage it was made at, and when.
    scout_tint: (Vec<f32>, u64, f64),
    tinted_at: Option<Instant>,
    /// The camera keeps this far from the wall (the session's safety margin).
    min_wall_mm: f64,
}

impl WindowCoverage {
    pub fn new(mesh: &CellMesh, cells: &Cells, min_wall_mm: f64) -> Self {
        let options = CoverageOptions::default();
        // Replaced by the view's own lens with each frame marked.
        let lens = Camera::lens(READING_FOV_DEG);
        WindowCoverage {
            on: true,
            reader: Reader::new(cells, lens, MARK_HEIGHT, MARK_HEIGHT),
            session: Coverage::new(mesh, options),
            flight: Coverage::new(mesh, options),
            reading: None,
            hold: 0,
            outline: Vec::new(),
            last: None,
            mark_ms: Vec::new(),
            budget_ms: 0.0,
            step_ms: 0.0,
            frames_asked: 0,
            frames_marked: 0,
            scout_tint: (Vec::new(), 0, f64::NAN),
            tinted_at: None,
            min_wall_mm,
        }
    }

    /// Marks what `camera` shows in a view of `size` pixels, unless the last frame marked
    /// showed exactly that, or the budget is spent: `frame_ms` is the window's last frame
    /// time, of which marking may take [`BUDGET_SHARE`].
    pub fn mark(
        &mut self,
        mesh: &CellMesh,
        cells: &Cells,
        camera: &Camera,
        size: [u32; 2],
        frame_ms: f64,
    ) {
        if !self.on {
            return;
        }
        let key = (camera.pose, camera.fov_y_deg, size);
        if self.last == Some(key) {
            return;
        }
        self.frames_asked += 1;
        let cost = self.mean_mark_ms();
        // A long stall (loading, a dialog) must not save up a burst of marking.
        let most = 2.0 * cost + 1.0;
        self.budget_ms = (self.budget_ms + BUDGET_SHARE * frame_ms).min(most);
        if self.budget_ms < cost {
            return;
        }
        self.last = Some(key);
        self.frames_marked += 1;
        let clock = Instant::now();
        self.mark_now(mesh, cells, camera, size);
        let ms = clock.elapsed().as_secs_f64() * 1e3;
        self.budget_ms -= ms;
        self.mark_ms.push(ms);
    }

    /// Marks what `camera` shows in a view of `size` pixels, whatever the budget.
    fn mark_now(&mut self, mesh: &CellMesh, cells: &Cells, camera: &Camera, size: [u32; 2]) {
        let width = ((MARK_HEIGHT as f64 * size[0] as f64 / size[1].max(1) as f64).round() as u32)
            .clamp(16, 4 * MARK_HEIGHT);
        self.reader.set_lens(*camera, width, MARK_HEIGHT);
        self.reader
            .show(mesh, cells, camera.pose, &mut self.session);
        // The same frame marks the flight's coverage.
        let frame = self.reader.frame();
        let view = voyage_view::View::new(camera, width, MARK_HEIGHT);
        self.flight.mark(frame, &view, mesh);
    }

    /// A two-way reading is under way.
    pub fn reading_running(&self) -> bool {
        self.reading.as_ref().is_some_and(|r| !r.is_done())
    }

    /// Mean time to mark a frame (ms), over the frames marked.
    pub fn mean_mark_ms(&self) -> f64 {
        if self.mark_ms.is_empty() {
            0.0
        } else {
            self.mark_ms.iter().sum::<f64>() / self.mark_ms.len() as f64
        }
    }

    /// What the report says of coverage.
    pub fn report(&self) -> CoverageReport {
        CoverageReport {
            on: self.on,
            session_pct: self.session.percent(),
            flight_pct: self.flight.percent(),
            mark_ms: self.mean_mark_ms(),
            step_ms: self.step_ms,
            frames_asked: self.frames_asked,
            frames_marked: self.frames_marked,
            reading: self.reading.as_ref().map(|r| ReadingReport {
                stage: match r.progress().step {
                    ReadingStep::Read(d) => d.name(),
                    ReadingStep::Review(_) => "review",
                    ReadingStep::Done => "done",
                }
                .into(),
                one_way_pct: r.one_way_pct(),
                two_way_pct: r.two_way_pct(),
                after_review_pct: r.after_review_pct(),
                patches: r.listed_patches(),
                visits: r.visits(),
                glances: r.glances(),
            }),
        }
    }

    /// Starts the two-way reading afresh (the reading's own lens and frames, as the CLI's).
    pub fn start_reading(&mut self, scene: &Scene<BrickStore>) -> voyage_core::Result<()> {
        self.reading = Some(ReadingRun::standard(scene)?);
        self.hold = 0;
        self.flight.clear();
        Ok(())
    }

    /// Stops the reading where it is; what it showed stays in the session's coverage.
    pub fn stop_reading(&mut self) {
        if let Some(r) = self.reading.take() {
            self.session.union(r.seen());
        }
        self.outline.clear();
    }

    /// One frame of the reading: its next move, or None while the last one is held on
    /// screen or no reading runs.
    pub fn step_reading(
        &mut self,
        scene: &Scene<BrickStore>,
    ) -> voyage_core::Result<Option<ReadingMove>> {
        let Some(r) = &mut self.reading else {
            return Ok(None);
        };
        if r.is_done() {
            return Ok(None);
        }
        if self.hold > 0 {
            self.hold -= 1;
            return Ok(None);
        }
        let clock = Instant::now();
        let step = r.step(scene)?;
        let ms = clock.elapsed().as_secs_f64() * 1e3;
        self.step_ms = if self.step_ms == 0.0 {
            ms
        } else {
            0.95 * self.step_ms + 0.05 * ms
        };
        match step {
            ReadingMove::Glance(_) => self.hold = GLANCE_FRAMES,
            ReadingMove::Visit(_) => {
                self.hold = DWELL_FRAMES;
                if let Some(v) = r.last_visit() {
                    self.outline = v.patch.outline(scene.mesh);
                }
            }
            ReadingMove::Done => {
                // The session has seen all the reading showed.
                self.session.union(r.seen());
                self.outline.clear();
            }
            ReadingMove::Fly(_) => {}
        }
        Ok(Some(step))
    }

    /// The largest unseen patch of the session (of the [`NEXT_TRIES`] largest) with a pose
    /// whose frame shows some of it ([`patch_pose`], as the reading's review chooses, through
    /// the window's lens), with that pose; else the largest a pose sees, or the largest, with
    /// None. None when nothing is left. Its outline is kept for the view. At most
    /// [`NEXT_TRIES`] × [`voyage_view::POSES_PER_VISIT`] frames of [`MARK_HEIGHT`] rows
    /// (about 2 ms each) are drawn for one click.
    pub fn next_patch(&mut self, mesh: &CellMesh, study: &Study) -> Option<(Patch, Option<Pose>)> {
        let lumen = Lumen::of(study, self.min_wall_mm);
        let patches = self.session.patches(mesh);
        let mut seen_from = None;
        let mut showing = None;
        for p in patches.iter().take(NEXT_TRIES) {
            let (pose, shown) = patch_pose(
                &mut self.reader,
                mesh,
                &study.cells,
                p,
                &lumen,
                &mut self.session,
            );
            if shown > 0.0 {
                showing = Some((p.clone(), pose));
                break;
            }
            if seen_from.is_none() && pose.is_some() {
                seen_from = Some((p.clone(), pose));
            }
        }
        let (patch, pose) = showing
            .or(seen_from)
            .or_else(|| patches.into_iter().next().map(|p| (p, None)))?;
        self.outline = patch.outline(mesh);
        Some((patch, pose))
    }

    /// The scout's colouring (see [`ScoutMesh::unseen_shares`]), made again when the session's
    /// coverage has moved by [`TINT_STEP_PCT`], at most every [`TINT_EVERY_S`]: a new
    /// colouring costs a pass over the surface and a redraw of the scout image.
    pub fn scout_tint(&mut self, mesh: &CellMesh, scout: &ScoutMesh) -> (&[f32], u64) {
        let pct = self.session.percent();
        let (_, version, at) = &self.scout_tint;
        let due = self
            .tinted_at
            .is_none_or(|t| t.elapsed().as_secs_f64() >= TINT_EVERY_S);
        if at.is_nan() || due && (pct - at).abs() >= TINT_STEP_PCT {
            self.tinted_at = Some(Instant::now());
            let shares = scout.unseen_shares(&self.session, mesh);
            self.scout_tint = (shares, version + 1, pct);
        }
        (&self.scout_tint.0, self.scout_tint.1)
    }
}

/// The scout is coloured again when the session's coverage has moved this far (percentage
/// points), and at most this often (seconds).
const TINT_STEP_PCT: f64 = 0.5;
const TINT_EVERY_S: f64 = 2.0;
