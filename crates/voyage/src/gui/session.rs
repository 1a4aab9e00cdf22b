//! One open study in the navigator: the preprocessed colon, the submarine flying in it, and
//! what the window needs beside (the scout's light mesh, the cells' visibility state).
//! No egui here: the panels read and steer a `Session`.

use std::sync::OnceLock;

use glam::DVec3;
use voyage_core::{Study, Volume};
use voyage_nav::{
    Autopilot, BrickStore, Camera, Direction, FlightOptions, Input, Pose, PotentialField,
    Submarine, potential_field, start_pose,
};
use voyage_view::{CellMesh, ReadingMove, Scene, ScoutMesh, Strategy, Visibility};

use super::coverage::WindowCoverage;

/// Longest simulated step of one displayed frame: a slow frame must not fling the
/// submarine (the physics sub-steps anyway; this keeps the flight's pace steady).
const MAX_FRAME_S: f64 = 1.0 / 15.0;

/// How far down the colon a jump or a slice click looks (mm along the centerline).
const LOOK_AHEAD_MM: f64 = 20.0;
/// A slice click's viewing spot stands at least this fraction of the local radius (the
/// centerline's distance to the wall) from the wall.
const SPOT_RADIUS_FRACTION: f64 = 0.6;
/// The nearest centerline points tried for one in sight of a slice click, and the step of
/// the line of sight to it (mm).
const SPOT_CANDIDATES: usize = 64;
const SPOT_STEP_MM: f64 = 0.5;

pub struct Session {
    /// What the report says of the exam: its name (the file name shown in the title, never a
    /// patient name), series, date and corrections by hand.
    pub exam: voyage_export::Exam,
    /// The series it was opened from, when the input held several (one position of an
    /// exam): a correction opens that one again.
    pub series_uid: Option<String>,
    /// The user's points (seeds, exclusions, ends, position) it was made with: a correction
    /// adds to them.
    pub points: crate::open::PointArgs,
    pub study: Study,
    pub field: PotentialField<BrickStore>,
    pub mesh: CellMesh,
    pub scout: ScoutMesh,
    pub vis: Visibility,
    pub sub: Submarine,
    pub pilot: Autopilot,
    pub opts: FlightOptions,
    /// The automatic flight is running (the field's pull toward the goal is on).
    pub playing: bool,
    /// The goal of the current direction was reached (the flight stopped there).
    pub reached: bool,
    /// Vertical field of view (degrees).
    pub fov: f64,
    /// Where the flight of the current direction starts.
    pub start: Pose,
    /// What the frames shown have shown of the mucosa, and the two-way reading.
    pub coverage: WindowCoverage,
    /// The cleansed CT, made the first time the translucency view asks for it.
    cleansed: OnceLock<Volume<i16>>,
    /// The view's field of view before the reading took its own lens.
    fov_before_reading: Option<f64>,
}

impl Session {
    /// The CT the surface was cut from: the cleansed one in a tagged exam (a copy, made once).
    pub fn surface_ct(&self) -> &Volume<i16> {
        if self.study.cleansing.is_empty() {
            return &self.study.ct;
        }
        self.cleansed.get_or_init(|| self.study.cleansed_ct())
    }

    /// The bridged gap the submarine is in, if any.
    pub fn collapsed_here(&self) -> Option<&voyage_core::Gap> {
        let x = self.sub.state.x;
        let cl = &self.study.centerline;
        let (i, _) = cl
            .points_mm
            .iter()
            .enumerate()
            .map(|(i, p)| (i, glam::DVec3::from_array(*p).distance_squared(x)))
            .min_by(|a, b| a.1.total_cmp(&b.1))?;
        self.study.gap_at(cl.arc_mm[i])
    }

    /// Everything the window needs for a preprocessed study; the submarine waits at the
    /// rectum, looking up the colon.
    pub fn new(exam: voyage_export::Exam, study: Study) -> anyhow::Result<Self> {
        let opts = FlightOptions {
            keep_poses: false,
            ..FlightOptions::for_study(&study)
        };
        let field = potential_field(&study, opts.safety.min_wall_mm)?;
        let mut mesh = CellMesh::new(&study.surface, &study.cells);
        // Per-cell vertex lists: the CPU rasterizer's fast path (coverage, the CPU view).
        mesh.index_cells();
        let coverage = WindowCoverage::new(&mesh, &study.cells, opts.safety.min_wall_mm);
        let scout = ScoutMesh::new(&study.surface.mesh, 4.0);
        let vis = Visibility::new(&study.cells, Strategy::Ours);
        let dir = Direction::Forward;
        let start = start_pose(&field, &study.centerline, dir, &opts)?;
        let mut sub = Submarine::new(&field, start, opts.safety)?;
        sub.potential = opts.potential;
        sub.dynamics = opts.dynamics;
        sub.modes = opts.modes;
        sub.direction = dir;
        let dt0 = field
            .sample(start.position, dir)
            .dt
            .unwrap_or(f64::INFINITY);
        let mut pilot = Autopilot::new(&study.centerline, dir, &opts, start.position, dt0);
        pilot.fit_reach(&field, dir, opts.safety.min_wall_mm);
        Ok(Session {
            exam,
            series_uid: None,
            points: Default::default(),
            study,
            field,
            mesh,
            scout,
            vis,
            sub,
            pilot,
            opts,
            playing: false,
            reached: false,
            fov: 90.0,
            start,
            coverage,
            cleansed: OnceLock::new(),
            fov_before_reading: None,
        })
    }

    pub fn pose(&self) -> Pose {
        self.sub.pose()
    }

    pub fn camera(&self) -> Camera {
        Camera::new(self.pose()).with_fov(self.fov)
    }

    pub fn direction(&self) -> Direction {
        self.sub.direction
    }

    /// Dt toward the current goal at the submarine (mm).
    pub fn dt_to_goal(&self) -> f64 {
        self.field
            .sample(self.sub.state.x, self.sub.direction)
            .dt
            .unwrap_or(f64::INFINITY)
    }

    /// Turns the flight around (rectum → cecum or back) from where the submarine is; when it
    /// already stands at the new goal (cecum → rectum chosen at the rectum, where a study
    /// opens), it goes to the new start instead, so that there is a flight to make.
    pub fn set_direction(&mut self, dir: Direction) {
        if dir == self.sub.direction {
            return;
        }
        self.sub.direction = dir;
        self.reached = false;
        self.coverage.flight.clear();
        let x = self.sub.state.x;
        self.pilot = Autopilot::new(
            &self.study.centerline,
            dir,
            &self.opts,
            x,
            self.dt_to_goal(),
        );
        self.pilot
            .fit_reach(&self.field, dir, self.opts.safety.min_wall_mm);
        self.pilot.restart(self.sub.state.t, self.dt_to_goal(), x);
        if let Ok(p) = start_pose(&self.field, &self.study.centerline, dir, &self.opts) {
            self.start = p;
        }
        if self.dt_to_goal() <= self.pilot.reach_mm {
            let playing = self.playing;
            self.place(self.start);
            self.playing = playing;
        }
    }

    /// Starts or stops the automatic flight; it runs on from wherever the submarine is.
    pub fn set_playing(&mut self, on: bool) {
        if on && !self.playing {
            self.reached = false;
            self.pilot
                .restart(self.sub.state.t, self.dt_to_goal(), self.sub.state.x);
        }
        self.playing = on;
    }

    /// Advances the submarine by one displayed frame of `dt` seconds. `user` is the force of
    /// a click-and-hold and the torque of a right-drag (paper Eq. 3–4). While paused the
    /// potential field is off and only the user moves the submarine.
    pub fn step(&mut self, dt: f64, user: &Input) {
        let dt = dt.clamp(0.0, MAX_FRAME_S);
        let steering = user.force != DVec3::ZERO || user.torque != DVec3::ZERO;
        let mut input = *user;
        if self.playing {
            let dt_now = self.dt_to_goal();
            if dt_now <= self.pilot.reach_mm {
                self.playing = false;
                self.reached = true;
            } else if steering || self.sub.modes.still {
                // Still mode holds the camera where it is: the autopilot does not take it
                // for stuck and glide it on.
                self.pilot
                    .restart(self.sub.state.t, dt_now, self.sub.state.x);
            } else if let Some(pose) =
                self.pilot
                    .glide(self.sub.state.x, self.sub.state.t, dt_now, dt)
                && self.sub.glide_to(&self.field, pose, dt)
            {
                // A bridged gap, a neck or a place stuck for 5 s: the flight keeps to the path.
                self.pilot.watch_from(self.sub.state.t, self.dt_to_goal());
                self.pilot.forget_look();
                return;
            } else {
                input.force += self
                    .pilot
                    .input(
                        self.sub.state.t,
                        dt_now,
                        self.sub.state.x,
                        self.sub.potential.ct,
                    )
                    .force;
            }
        }
        // Paused, the field is switched off (Ct = Cs = 0): the camera stays where it is
        // unless the user pushes it, and a push glides to rest under friction. The safe set
        // still keeps it off the wall (Submarine::step clips every sub-step). Playing, ρ is
        // held within the lumen's radius (`FlightOptions::rho_per_radius`).
        // Playing, the view turns toward the centerline ahead; the user's click or drag
        // turns it while it lasts (the compass then follows the field, as the paper's), and
        // the view eases back after.
        let field = self.sub.potential;
        self.sub.look_at = if self.playing && !steering {
            Some(self.pilot.look(self.sub.state.x, dt))
        } else {
            self.pilot.forget_look();
            None
        };
        if self.playing {
            self.sub.potential.rho = self.pilot.rho(&field);
        } else {
            self.sub.potential.ct = 0.0;
            self.sub.potential.cs = 0.0;
        }
        self.sub.step(&self.field, dt, &input);
        self.sub.potential = field;
        self.pilot.moved_to(self.sub.state.x);
    }

    /// Puts the submarine at `x` at rest, looking along `forward`, if `x` is in the safe
    /// set; otherwise says why not.
    pub fn jump_to(&mut self, x: DVec3, forward: DVec3) -> Result<(), String> {
        if !self.sub.is_safe(&self.field, x) {
            return Err(format!(
                "({:.0}, {:.0}, {:.0}) mm is not inside the colon at least {} mm from the wall",
                x.x, x.y, x.z, self.opts.safety.min_wall_mm
            ));
        }
        let up = -self.sub.dynamics.gravity;
        let pose = Pose::looking(x, forward, up);
        self.place(pose);
        Ok(())
    }

    /// Puts the submarine at rest at `pose` (which must be safe: a pose it had before).
    pub fn place(&mut self, pose: Pose) {
        self.follow(pose);
        self.vis.reset();
        self.pilot
            .restart(self.sub.state.t, self.dt_to_goal(), pose.position);
    }

    /// Jumps to centerline point `i`, looking down the colon toward the current goal.
    pub fn jump_to_centerline(&mut self, i: usize) -> Result<(), String> {
        let pts = &self.study.centerline.points_mm;
        if pts.is_empty() {
            return Err("the centerline is empty".into());
        }
        let i = i.min(pts.len() - 1);
        let p = DVec3::from_array(pts[i]);
        // The centerline can run closer to the wall than the safety margin where the lumen
        // is narrow; then the nearest safe point along the local cross-section would do, but
        // the plain answer is to refuse.
        self.jump_to(p, self.down_the_colon(i))
    }

    /// The view down the colon from centerline point `i` in the current direction: toward
    /// the centerline [`LOOK_AHEAD_MM`] on (a tangent over a few points follows the
    /// centerline's wiggles and can face the wall).
    fn down_the_colon(&self, i: usize) -> DVec3 {
        let cl = &self.study.centerline;
        let p = DVec3::from_array(cl.points_mm[i]);
        let ahead = |forward: bool| {
            let arc = cl.arc_mm[i]
                + if forward {
                    LOOK_AHEAD_MM
                } else {
                    -LOOK_AHEAD_MM
                };
            let j = cl
                .arc_mm
                .partition_point(|&a| a < arc)
                .min(cl.points_mm.len() - 1);
            DVec3::from_array(cl.points_mm[j]) - p
        };
        let forward = self.sub.direction == Direction::Forward;
        // At the goal's end, the view along the way back, turned round.
        let d = ahead(forward);
        if d.length() > 1.0 {
            d
        } else {
            -ahead(!forward)
        }
    }

    /// Moves to a viewing spot for the lumen point `x` (a slice click): on the line from `x`
    /// toward the nearest centerline point it sees, the first point at least
    /// [`SPOT_RADIUS_FRACTION`] of the local radius from the wall, looking down the colon in
    /// the current direction. A click by the wall does not put the camera against it.
    pub fn move_to_spot(&mut self, x: DVec3) -> Result<(), String> {
        let ds = |p: DVec3| self.study.ds.sample(p) as f64;
        if ds(x) <= 0.0 {
            return Err(format!(
                "({:.0}, {:.0}, {:.0}) mm is not inside the colon",
                x.x, x.y, x.z
            ));
        }
        let cl = &self.study.centerline.points_mm;
        let mut near: Vec<(f64, usize)> = (0..cl.len())
            .map(|i| (DVec3::from_array(cl[i]).distance_squared(x), i))
            .collect();
        near.sort_by(|a, b| a.0.total_cmp(&b.0));
        // The nearest centerline point in the same stretch of lumen: the line to it stays in
        // air (a loop beyond the wall can be nearer).
        let seen = near.iter().take(SPOT_CANDIDATES).find_map(|&(_, i)| {
            let c = DVec3::from_array(cl[i]);
            let steps = (c.distance(x) / SPOT_STEP_MM).ceil().max(1.0) as usize;
            let line: Vec<DVec3> = (0..=steps)
                .map(|k| x.lerp(c, k as f64 / steps as f64))
                .collect();
            line.iter().all(|&q| ds(q) > 0.0).then_some((i, line))
        });
        let Some((i, line)) = seen else {
            return Err("no centerline in sight of that point".into());
        };
        let want = SPOT_RADIUS_FRACTION * ds(DVec3::from_array(cl[i]));
        let spot = line
            .iter()
            .copied()
            .find(|&q| ds(q) >= want && self.sub.is_safe(&self.field, q))
            .unwrap_or(DVec3::from_array(cl[i]));
        self.jump_to(spot, self.down_the_colon(i))
    }

    /// Back to the start of the current direction's flight.
    pub fn restart(&mut self) {
        self.place(self.start);
        self.playing = false;
        self.coverage.flight.clear();
    }

    /// Marks what `camera` shows in a view of `size` pixels as seen (`frame_ms`: the window's
    /// last frame time, which bounds what marking may cost).
    pub fn mark_shown(&mut self, camera: &Camera, size: [u32; 2], frame_ms: f64) {
        self.coverage
            .mark(&self.mesh, &self.study.cells, camera, size, frame_ms);
    }

    /// Shows the two-way reading's next move, if it has one this frame.
    pub fn step_reading(&mut self) -> Result<(), String> {
        let scene = Scene {
            study: &self.study,
            mesh: &self.mesh,
            field: &self.field,
        };
        let step = self
            .coverage
            .step_reading(&scene)
            .map_err(|e| e.to_string());
        match step? {
            None | Some(ReadingMove::Done) => {}
            Some(ReadingMove::Fly(pose)) => {
                let direction = self.coverage.reading.as_ref().and_then(|r| r.direction());
                if let Some(d) = direction {
                    self.set_direction(d);
                }
                self.follow(pose);
            }
            Some(ReadingMove::Glance(pose) | ReadingMove::Visit(pose)) => {
                self.show_from(pose);
            }
        }
        if !self.coverage.reading_running() {
            self.end_reading_lens();
        }
        Ok(())
    }

    /// Starts the two-way reading: rectum → cecum, cecum → rectum, then the review. The view
    /// takes the reading's lens while it runs, so that it shows what is counted.
    pub fn start_reading(&mut self) -> Result<(), String> {
        let scene = Scene {
            study: &self.study,
            mesh: &self.mesh,
            field: &self.field,
        };
        self.coverage
            .start_reading(&scene)
            .map_err(|e| e.to_string())?;
        self.set_playing(false);
        if let Some(r) = &self.coverage.reading {
            self.fov_before_reading.get_or_insert(self.fov);
            self.fov = r.lens().fov_y_deg;
        }
        Ok(())
    }

    /// Stops the two-way reading where it is.
    pub fn stop_reading(&mut self) {
        self.coverage.stop_reading();
        self.end_reading_lens();
    }

    fn end_reading_lens(&mut self) {
        if let Some(fov) = self.fov_before_reading.take() {
            self.fov = fov;
        }
    }

    /// Stands at the next frame of a flight drawn elsewhere (the reading's): the culling
    /// state carries over, as from one frame of a flight to the next.
    fn follow(&mut self, pose: Pose) {
        let t = self.sub.state.t;
        self.sub.state = voyage_nav::State::at(pose);
        self.sub.state.t = t;
        self.reached = false;
    }

    /// Stops and stands at `pose` when it is in the safe set (a review's or a patch's pose
    /// is in the lumen clear of the wall by Ds; the safe set is checked all the same).
    pub fn show_from(&mut self, pose: Pose) -> bool {
        if !self.sub.is_safe(&self.field, pose.position) {
            return false;
        }
        self.set_playing(false);
        self.place(pose);
        true
    }

    /// Whether the straight segment `from → to` stays in the lumen, ignoring its last
    /// `skip_end_mm` (a point on the wall is seen although its own voxel is wall).
    pub fn line_of_sight(&self, from: DVec3, to: DVec3, skip_end_mm: f64) -> bool {
        let lumen = &self.study.segmentation.lumen;
        let g = lumen.geometry();
        let len = from.distance(to);
        let step = 0.5 * g.spacing_vec().min_element();
        let n = ((len - skip_end_mm).max(0.0) / step).ceil() as usize;
        let dims = lumen.dims();
        // Index space is an affine image of local mm: march there, one multiply-add per axis
        // per sample (the overlays test hundreds of segments a frame).
        let (a, b) = (g.local_to_index(from), g.local_to_index(to));
        let d = (b - a) * (step / len.max(f64::MIN_POSITIVE));
        for s in 1..n {
            // The nearest voxel: + 0.5 and truncate, where `round` would be a libm call on
            // baseline x86-64.
            let h = a + d * s as f64 + 0.5;
            if h.min_element() < 0.0
                || h.x >= dims[0] as f64
                || h.y >= dims[1] as f64
                || h.z >= dims[2] as f64
            {
                return false;
            }
            if lumen.get(h.x as usize, h.y as usize, h.z as usize) == 0 {
                return false;
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use voyage_core::{PrepOptions, prepare};

    fn pipe_exam() -> voyage_export::Exam {
        voyage_export::Exam {
            name: "pipe".into(),
            ..Default::default()
        }
    }

    /// The plain form: each sample mapped from mm to the nearest voxel.
    fn reference(s: &Session, from: DVec3, to: DVec3, skip_end_mm: f64) -> bool {
        let lumen = &s.study.segmentation.lumen;
        let g = lumen.geometry();
        let len = from.distance(to);
        let step = 0.5 * g.spacing_vec().min_element();
        let n = ((len - skip_end_mm).max(0.0) / step).ceil() as usize;
        let dims = lumen.dims();
        (1..n).all(|k| {
            let ijk = g
                .local_to_index(from + (to - from) * (k as f64 * step / len))
                .round();
            ijk.min_element() >= 0.0
                && ijk.x < dims[0] as f64
                && ijk.y < dims[1] as f64
                && ijk.z < dims[2] as f64
                && lumen.get(ijk.x as usize, ijk.y as usize, ijk.z as usize) != 0
        })
    }

    /// The view's angle to the centerline's way on (degrees).
    fn off_the_way(s: &Session) -> f64 {
        voyage_nav::looking(&s.study, s.direction(), &[s.pose()])
            .view_angle_deg
            .median
    }

    #[test]
    fn a_drag_turns_the_flying_view_away_while_it_lasts_and_the_view_eases_back() {
        let p = voyage_phantom::pipe(1).unwrap();
        let study = prepare(p.ct, &PrepOptions::default(), |_| {}).unwrap();
        let mut s = Session::new(pipe_exam(), study).unwrap();
        let frame = 1.0 / 30.0;
        s.set_playing(true);
        for _ in 0..45 {
            s.step(frame, &Input::default());
        }
        let flying = off_the_way(&s);
        assert!(
            flying <= 15.0,
            "flying, the view is {flying:.0}° off the way"
        );
        // A right-drag sideways at 1 rad/s for half a second (as the window makes it).
        for _ in 0..15 {
            let torque = -s.pose().y_body() * s.sub.dynamics.ka;
            s.step(
                frame,
                &Input {
                    force: DVec3::ZERO,
                    torque,
                },
            );
        }
        let dragged = off_the_way(&s);
        assert!(
            dragged >= flying + 15.0,
            "the drag turned the view only to {dragged:.0}° (from {flying:.0}°)"
        );
        assert!(s.playing, "a drag does not stop the flight");
        // Released: back down the lumen within a second, without swinging past.
        let mut after = Vec::new();
        for _ in 0..30 {
            s.step(frame, &Input::default());
            after.push(off_the_way(&s));
        }
        assert!(
            after[after.len() - 1] <= 15.0,
            "a second after the drag the view is still {:.0}° off the way",
            after[after.len() - 1]
        );
    }

    /// Still mode holds the camera while the flight plays: the autopilot does not take the
    /// camera that stands still for wedged and glide it on.
    #[test]
    fn still_mode_holds_the_flying_camera_for_good() {
        let p = voyage_phantom::pipe(1).unwrap();
        let study = prepare(p.ct, &PrepOptions::default(), |_| {}).unwrap();
        let mut s = Session::new(pipe_exam(), study).unwrap();
        let frame = 1.0 / 30.0;
        s.set_playing(true);
        for _ in 0..30 {
            s.step(frame, &Input::default());
        }
        s.sub.modes.still = true;
        let held = s.sub.state.x;
        for _ in 0..(3.0 * voyage_nav::WEDGED_S / frame) as usize {
            s.step(frame, &Input::default());
        }
        assert!(
            s.playing && s.pilot.rescues.is_empty(),
            "rescued while still"
        );
        assert!(
            s.sub.state.x.distance(held) < 1e-9,
            "moved {:.1} mm while still",
            s.sub.state.x.distance(held)
        );
    }

    #[test]
    fn line_of_sight_agrees_with_the_voxel_walk_and_sees_along_the_pipe_not_through_its_wall() {
        let p = voyage_phantom::pipe(1).unwrap();
        let study = prepare(p.ct, &PrepOptions::default(), |_| {}).unwrap();
        let s = Session::new(pipe_exam(), study).unwrap();
        let pts: Vec<DVec3> = s
            .study
            .centerline
            .points_mm
            .iter()
            .map(|&p| DVec3::from_array(p))
            .collect();
        // A few mm along the centerline: seen. From inside to 100 mm sideways: not.
        let (a, b) = (pts[pts.len() / 2], pts[pts.len() / 2 + 5]);
        assert!(s.line_of_sight(a, b, 0.0));
        let side = (b - a).any_orthonormal_vector();
        assert!(!s.line_of_sight(a, a + 100.0 * side, 0.0));
        // Many segments between centerline points, and out toward the wall and beyond.
        let mut rng = voyage_core::rng::Rng::new(7, 1);
        let (mut seen, mut n) = (0, 0);
        for _ in 0..3000 {
            let i = rng.range(0.0, (pts.len() - 1) as f64) as usize;
            let j = rng.range(0.0, (pts.len() - 1) as f64) as usize;
            let to = pts[j]
                + DVec3::new(
                    rng.range(-20.0, 20.0),
                    rng.range(-20.0, 20.0),
                    rng.range(-20.0, 20.0),
                );
            let skip = if rng.range(0.0, 1.0) < 0.5 { 0.0 } else { 1.5 };
            let got = s.line_of_sight(pts[i], to, skip);
            assert_eq!(
                got,
                reference(&s, pts[i], to, skip),
                "segment {:?} → {:?}",
                pts[i],
                to
            );
            seen += got as usize;
            n += 1;
        }
        assert!(seen > n / 20 && seen < n, "{seen} of {n} segments clear");
    }
}
