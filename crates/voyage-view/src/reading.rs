//! The reading: both automatic flights, each frame drawn and marked, glancing around as
//! readers do, then a review that visits every unseen patch. One engine, [`ReadingRun`],
//! stepped a move at a time: `voyage coverage` and `voyage report` run it to its end
//! ([`read_both_ways`]), the window steps it once per frame and shows each move. Both read
//! through the same lens ([`READING_FOV_DEG`], [`READING_PX`]) with the same options, so
//! their figures and C-RADS category are the same for the same study.

use voyage_core::{Result, Study};
use voyage_nav::{
    Camera, Direction, DistanceStore, Flight, FlightOptions, FlightRun, Pose, PotentialField,
    potential_field,
};

use crate::{
    coverage::{
        Coverage, CoverageOptions, Glances, Lumen, Patch, READING_FOV_DEG, Reader, viewing_poses,
    },
    mesh::CellMesh,
};

/// Side of the square frames the reading draws and marks (pixels).
pub const READING_PX: u32 = 256;

/// Review rounds: a patch a pose showed only in part is visited again, from the rest's own
/// viewpoint.
pub const REVIEW_ROUNDS: usize = 30;

/// Poses a review visit tries, in turn, until one shows something new.
pub const POSES_PER_VISIT: usize = 8;

/// What a reading reads: the same study, surface and potential field at every step.
pub struct Scene<'a, S: DistanceStore> {
    pub study: &'a Study,
    pub mesh: &'a CellMesh,
    pub field: &'a PotentialField<S>,
}

/// One patch as the review met it.
#[derive(Clone, Debug)]
pub struct Visit {
    pub patch: Patch,
    /// The pose shown, None where no viewpoint sees the patch.
    pub pose: Option<Pose>,
    /// Area of the surface the visit newly showed (mm²).
    pub shown_mm2: f64,
}

/// What the reading did in one step; each pose was drawn and marked before it is returned.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ReadingMove {
    /// A frame of the automatic flight.
    Fly(Pose),
    /// A look around from the flight's last frame; the flight goes on from that frame.
    Glance(Pose),
    /// The review stands here to show an unseen patch ([`ReadingRun::last_visit`]).
    Visit(Pose),
    /// The reading is over.
    Done,
}

/// How far a reading has got, for a progress bar: the step it is at, and of that step's
/// `total` units (mm of a flight's way, patches of a review round) how many are done.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReadingProgress {
    pub step: ReadingStep,
    pub done: usize,
    pub total: usize,
}

/// The steps of a reading, in order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReadingStep {
    /// The automatic flight, its frames drawn and marked as it goes.
    Read(Direction),
    /// A review round visits the unseen patches (rounds from 0).
    Review(usize),
    Done,
}

impl ReadingStep {
    /// A few words for a progress line.
    pub fn describe(&self) -> String {
        match self {
            ReadingStep::Read(d) => format!("reading {}", d.name()),
            ReadingStep::Review(r) => format!("review, round {}", r + 1),
            ReadingStep::Done => "done".into(),
        }
    }
}

/// What a two-way reading with review showed.
pub struct Reading {
    /// The automatic flights, rectum → cecum then cecum → rectum.
    pub flights: [Flight; 2],
    /// The glances each flight took ([`Glances`]).
    pub glances: [usize; 2],
    /// What the first flight showed.
    pub one_way: Coverage,
    /// What both flights showed.
    pub two_way: Coverage,
    /// Both flights and the review.
    pub after_review: Coverage,
    /// The unseen patches of the two-way reading (at least `min_patch_mm2`), largest first,
    /// each with the pose the review showed it from and what that showed.
    pub patches: Vec<Visit>,
    /// Every visit of the review (its later rounds revisit what a first pose left).
    pub visits: usize,
}

enum Stage {
    Flying {
        run: Box<FlightRun>,
        glances: Box<Glances>,
        /// The start pose has been shown.
        started: bool,
    },
    Reviewing {
        round: usize,
        queue: Vec<Patch>,
        next: usize,
        /// Area this round's visits newly showed (mm²).
        shown_mm2: f64,
    },
    Done,
}

/// A reading under way: rectum → cecum, cecum → rectum, then the review, one move per
/// [`ReadingRun::step`].
pub struct ReadingRun {
    options: CoverageOptions,
    lens: Camera,
    flight_opts: FlightOptions,
    reader: Reader,
    stage: Stage,
    /// What the flight under way has shown; after the flights, what the review adds to
    /// both.
    seen: Coverage,
    one_way: Option<Coverage>,
    two_way: Option<Coverage>,
    flights: Vec<Flight>,
    glances: [usize; 2],
    visits: Vec<Visit>,
    /// Patches of the two-way reading that are listed (the review's first ones).
    listed: usize,
    /// Patches a visit showed nothing of, by centre triangle and size: later rounds leave
    /// them while they are the same (a patch that lost triangles has other anchors, so other
    /// poses).
    fruitless: std::collections::HashSet<(u32, usize)>,
}

impl ReadingRun {
    /// The reading every path of the program makes: the default options, through the
    /// reading lens at [`READING_PX`]².
    pub fn standard<S: DistanceStore>(scene: &Scene<S>) -> Result<ReadingRun> {
        let lens = Camera::lens(READING_FOV_DEG);
        ReadingRun::new(scene, CoverageOptions::default(), lens, READING_PX)
    }

    /// A reading with these options, through `lens` (its pose is replaced per frame) on
    /// square frames of `size` pixels. The flights are the study's automatic flights
    /// ([`FlightOptions::for_study`]); `scene.field` must keep their wall distance.
    pub fn new<S: DistanceStore>(
        scene: &Scene<S>,
        options: CoverageOptions,
        lens: Camera,
        size: u32,
    ) -> Result<ReadingRun> {
        let flight_opts = FlightOptions {
            keep_poses: false,
            ..FlightOptions::for_study(scene.study)
        };
        let cells = &scene.study.cells;
        let stage = flying(scene, Direction::Forward, &flight_opts, lens)?;
        Ok(ReadingRun {
            options,
            lens,
            reader: Reader::new(cells, lens, size, size),
            stage,
            seen: Coverage::new(scene.mesh, options),
            one_way: None,
            two_way: None,
            flights: Vec::new(),
            glances: [0; 2],
            visits: Vec::new(),
            listed: 0,
            fruitless: Default::default(),
            flight_opts,
        })
    }

    /// The wall distance the reading's flights keep (mm): the field must be made for it.
    pub fn min_wall_mm(study: &Study) -> f64 {
        FlightOptions::for_study(study).safety.min_wall_mm
    }

    /// The lens the reading looks through.
    pub fn lens(&self) -> Camera {
        self.lens
    }

    pub fn options(&self) -> &CoverageOptions {
        &self.options
    }

    /// The next move, drawn and marked.
    pub fn step<S: DistanceStore>(&mut self, scene: &Scene<S>) -> Result<ReadingMove> {
        loop {
            let stage = std::mem::replace(&mut self.stage, Stage::Done);
            match stage {
                Stage::Flying {
                    mut run,
                    mut glances,
                    started,
                } => {
                    let pose = if started {
                        run.step(scene.field)
                    } else {
                        Some(run.pose())
                    };
                    let Some(pose) = pose else {
                        self.end_flight(scene, run)?;
                        continue;
                    };
                    let way = usize::from(run.direction() == Direction::Backward);
                    let cells = &scene.study.cells;
                    self.reader.show(scene.mesh, cells, pose, &mut self.seen);
                    let glance = if self.options.look_around {
                        glances.next(scene.mesh, cells, pose, &mut self.seen)
                    } else {
                        None
                    };
                    self.stage = Stage::Flying {
                        run,
                        glances,
                        started: true,
                    };
                    let Some(glance) = glance else {
                        return Ok(ReadingMove::Fly(pose));
                    };
                    self.reader.show(scene.mesh, cells, glance, &mut self.seen);
                    self.glances[way] += 1;
                    return Ok(ReadingMove::Glance(glance));
                }
                Stage::Reviewing {
                    round,
                    queue,
                    mut next,
                    mut shown_mm2,
                } => {
                    let lumen = Lumen::of(scene.study, self.flight_opts.safety.min_wall_mm);
                    let mut shown_pose = None;
                    while next < queue.len() && shown_pose.is_none() {
                        let patch = queue[next].clone();
                        next += 1;
                        let key = (patch.center_triangle, patch.triangles.len());
                        if self.fruitless.contains(&key) {
                            continue;
                        }
                        let (pose, shown) =
                            self.visit(scene.mesh, &scene.study.cells, &patch, &lumen);
                        if shown == 0.0 {
                            self.fruitless.insert(key);
                        }
                        shown_mm2 += shown;
                        self.visits.push(Visit {
                            patch,
                            pose,
                            shown_mm2: shown,
                        });
                        shown_pose = pose;
                    }
                    if let Some(pose) = shown_pose {
                        self.stage = Stage::Reviewing {
                            round,
                            queue,
                            next,
                            shown_mm2,
                        };
                        return Ok(ReadingMove::Visit(pose));
                    }
                    // The round is over: another, for what its poses left, while they show more.
                    if shown_mm2 > 0.0 && round + 1 < REVIEW_ROUNDS {
                        self.stage = self.review_round(scene.mesh, round + 1);
                    }
                }
                Stage::Done => return Ok(ReadingMove::Done),
            }
        }
    }

    /// Runs the reading to its end, telling `progress` before each move.
    pub fn run_to_end<S: DistanceStore>(
        &mut self,
        scene: &Scene<S>,
        mut progress: impl FnMut(ReadingProgress),
    ) -> Result<()> {
        loop {
            progress(self.progress());
            if self.step(scene)? == ReadingMove::Done {
                return Ok(());
            }
        }
    }

    /// A flight has ended: the next one, or the review.
    fn end_flight<S: DistanceStore>(
        &mut self,
        scene: &Scene<S>,
        run: Box<FlightRun>,
    ) -> Result<()> {
        let direction = run.direction();
        self.flights.push(run.finish(scene.field));
        if direction == Direction::Forward {
            self.one_way = Some(self.seen.clone());
            self.seen.clear();
            self.stage = flying(scene, Direction::Backward, &self.flight_opts, self.lens)?;
            return Ok(());
        }
        // `seen` holds what the way back showed: joined to the first flight's, both ways.
        let mut both = self.one_way.clone().unwrap_or_else(|| self.seen.clone());
        both.union(&self.seen);
        self.listed = both.patches(scene.mesh).len();
        self.two_way = Some(both.clone());
        self.seen = both;
        self.stage = self.review_round(scene.mesh, 0);
        Ok(())
    }

    /// A visit to `patch` ([`patch_pose`]), what it shows marked.
    fn visit(
        &mut self,
        mesh: &CellMesh,
        cells: &voyage_core::Cells,
        patch: &Patch,
        lumen: &Lumen,
    ) -> (Option<Pose>, f64) {
        let (pose, shown) = patch_pose(&mut self.reader, mesh, cells, patch, lumen, &mut self.seen);
        if shown > 0.0 {
            self.reader.mark_drawn(mesh, &mut self.seen);
        }
        (pose, shown)
    }

    /// Round `round` of the review: the unseen patches now, largest first (the listed ones
    /// lead), or the end when none is left.
    fn review_round(&self, mesh: &CellMesh, round: usize) -> Stage {
        let queue = self.seen.review_targets(mesh);
        if queue.is_empty() {
            return Stage::Done;
        }
        Stage::Reviewing {
            round,
            queue,
            next: 0,
            shown_mm2: 0.0,
        }
    }

    /// Where the reading is.
    pub fn progress(&self) -> ReadingProgress {
        let (step, done, total) = match &self.stage {
            Stage::Flying { run, .. } => {
                let total = run.start_dt_mm().max(1.0);
                let done = (run.start_dt_mm() - run.dt_mm()).clamp(0.0, total);
                (ReadingStep::Read(run.direction()), done, total)
            }
            Stage::Reviewing {
                round, queue, next, ..
            } => (
                ReadingStep::Review(*round),
                *next as f64,
                queue.len() as f64,
            ),
            Stage::Done => (ReadingStep::Done, 1.0, 1.0),
        };
        ReadingProgress {
            step,
            done: done.round() as usize,
            total: total.round() as usize,
        }
    }

    /// The direction of the flight under way (None once the flights are over).
    pub fn direction(&self) -> Option<Direction> {
        match &self.stage {
            Stage::Flying { run, .. } => Some(run.direction()),
            _ => None,
        }
    }

    pub fn is_done(&self) -> bool {
        matches!(self.stage, Stage::Done)
    }

    /// Seen now by the reading's current part, in percent: the flight under way, or both
    /// flights with the review so far.
    pub fn seen_pct(&self) -> f64 {
        self.seen.percent()
    }

    /// Seen by the first flight, once it is over (percent).
    pub fn one_way_pct(&self) -> Option<f64> {
        self.one_way.as_ref().map(Coverage::percent)
    }

    /// Seen by both flights, once they are over (percent).
    pub fn two_way_pct(&self) -> Option<f64> {
        self.two_way.as_ref().map(Coverage::percent)
    }

    /// Seen by both flights and the review, once it is over (percent).
    pub fn after_review_pct(&self) -> Option<f64> {
        self.is_done()
            .then(|| self.two_way.as_ref().map(|_| self.seen.percent()))
            .flatten()
    }

    /// What the reading has shown so far, over all its parts: the session's coverage after
    /// the flights, the flight's before.
    pub fn seen(&self) -> &Coverage {
        &self.seen
    }

    /// The review's last visit.
    pub fn last_visit(&self) -> Option<&Visit> {
        self.visits.last()
    }

    /// Listed unseen patches after both flights, and the review's visits so far.
    pub fn listed_patches(&self) -> usize {
        self.listed
    }

    pub fn visits(&self) -> usize {
        self.visits.len()
    }

    /// Glances taken by the flights so far.
    pub fn glances(&self) -> usize {
        self.glances.iter().sum()
    }

    /// The reading's figures, once it is done (None before).
    pub fn into_reading(self) -> Option<Reading> {
        if !self.is_done() {
            return None;
        }
        let [forward, backward]: [Flight; 2] = self.flights.try_into().ok()?;
        let total_visits = self.visits.len();
        Some(Reading {
            flights: [forward, backward],
            glances: self.glances,
            one_way: self.one_way?,
            two_way: self.two_way?,
            after_review: self.seen,
            // The review's first round visits the listed patches first, in order.
            patches: self.visits.into_iter().take(self.listed).collect(),
            visits: total_visits,
        })
    }
}

/// Where to look at `patch` from: the first of its poses ([`viewing_poses`], at most
/// [`POSES_PER_VISIT`]) whose frame through `reader` would newly show something of `seen`,
/// with that area (mm²), its frame left drawn and unmarked; else the first pose, showing
/// nothing; None where no pose sees it. A pose whose pick meets the patch can still show
/// nothing `seen` counts (on `ctc/prone-tagged` with faster glides, a 5 500 mm² patch of the
/// ascending colon was visited from the same pose in 23 rounds). The review's visits and the
/// window's "next unseen" both choose here.
pub fn patch_pose(
    reader: &mut Reader,
    mesh: &CellMesh,
    cells: &voyage_core::Cells,
    patch: &Patch,
    lumen: &Lumen,
    seen: &mut Coverage,
) -> (Option<Pose>, f64) {
    let options = *seen.options();
    let mut poses = viewing_poses(patch, mesh, lumen, &options)
        .take(POSES_PER_VISIT)
        .peekable();
    let first = poses.peek().copied();
    match reader.first_showing(mesh, cells, poses, seen) {
        Some((pose, shown)) => (Some(pose), shown),
        None => (first, 0.0),
    }
}

/// The flight of `direction` about to start, looking around as it goes.
fn flying<S: DistanceStore>(
    scene: &Scene<S>,
    direction: Direction,
    opts: &FlightOptions,
    lens: Camera,
) -> Result<Stage> {
    let run = Box::new(FlightRun::new(
        scene.field,
        &scene.study.centerline,
        direction,
        opts,
    )?);
    Ok(Stage::Flying {
        run,
        glances: Box::new(Glances::new(&scene.study.cells, lens)),
        started: false,
    })
}

/// The reading of [`ReadingRun`] run to its end: both automatic flights, every frame drawn
/// at `size`² through `camera`'s lens and marked, then the review. `progress` hears before
/// each move.
pub fn read_both_ways(
    study: &Study,
    mesh: &CellMesh,
    options: CoverageOptions,
    camera: Camera,
    size: u32,
    progress: impl FnMut(ReadingProgress),
) -> Result<Reading> {
    let field = potential_field(study, ReadingRun::min_wall_mm(study))?;
    let scene = Scene {
        study,
        mesh,
        field: &field,
    };
    let mut run = ReadingRun::new(&scene, options, camera, size)?;
    run.run_to_end(&scene, progress)?;
    Ok(run
        .into_reading()
        .expect("a reading run to its end has its figures"))
}
