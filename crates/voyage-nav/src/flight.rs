//! Automatic flight: the submarine left to the potential field, from one end of the colon to
//! the other, at a fixed frame rate, with local minima of V (paper Fig. 3d) detected and
//! escaped.
//!
//! A **stall** is a stretch of `stall_window_s` simulated seconds in which Dt fell by less
//! than `stall_progress_mm`. The escape pulls the submarine toward a centerline point ahead
//! (out of the pocket, toward the goal) with a force of `escape_factor`·Ct for `escape_s`
//! seconds — the user's click of §3.3, made by the autopilot — 1.5 times harder for each
//! stall in a row. Where that does not free it ([`STUCK_S`] seconds without progress, or
//! [`WEDGED_S`] without moving at all), the autopilot glides on along the centerline (a
//! rescue). A flight that stalls `max_stalls` times, or runs past `max_sim_s`, ends
//! unreached (a permanent stall).

use std::time::Instant;

use glam::DVec3;
use serde::Serialize;

use crate::{
    camera::Pose,
    potential::{Direction, DistanceStore, PotentialField, PotentialParams},
    submarine::{Dynamics, Input, Look, Modes, Safety, Submarine},
};
use voyage_core::{Centerline, Error, Result};

#[derive(Clone, Debug)]
pub struct FlightOptions {
    pub fps: f64,
    pub potential: PotentialParams,
    pub dynamics: Dynamics,
    pub modes: Modes,
    pub safety: Safety,
    /// The goal is reached when Dt ≤ this (mm); None: 10 mm or the lumen radius at the goal,
    /// whichever is larger.
    pub reach_mm: Option<f64>,
    /// None: centerline length / 5 mm/s + 60 s.
    pub max_sim_s: Option<f64>,
    pub stall_window_s: f64,
    pub stall_progress_mm: f64,
    pub escape_s: f64,
    pub escape_factor: f64,
    pub max_stalls: usize,
    /// Keep every frame's pose (for trajectories and movies).
    pub keep_poses: bool,
    /// Stretches of the centerline (arc mm from the source) through bridged gaps, which the
    /// flight glides along at `glide_mm_s` (see [`Autopilot::glide`]).
    pub collapsed_spans: Vec<[f64; 2]>,
    /// The glide's speed (mm/s), about half the free flight's: toward and through a
    /// collapsed stretch the view is wall all round. At 10 mm/s 2.7 % of the real exam's
    /// forward frames saw only wall, most of them there; at 20 mm/s 1.5 % (BENCHMARKS.md,
    /// sixteenth session).
    pub glide_mm_s: f64,
    /// ρ of Eq. 2 is at most this many times the lumen's radius at the nearest centerline
    /// point (None: the potential's ρ everywhere). With ρ above the radius the wall's push
    /// acts on the centerline too and rises where the lumen narrows: a barrier along the
    /// way that Ct cannot climb (on ctc/prone-tagged, with Dt's ways kept off the wall:
    /// ρ = 25 mm everywhere, 6 and 5 stalls at tapers; at most 1.5 radii, none).
    pub rho_per_radius: Option<f64>,
}

impl Default for FlightOptions {
    fn default() -> Self {
        FlightOptions {
            fps: 30.0,
            potential: PotentialParams::default(),
            dynamics: Dynamics::default(),
            modes: Modes {
                compass: true,
                leveling: true,
                still: false,
            },
            safety: Safety::default(),
            reach_mm: None,
            max_sim_s: None,
            stall_window_s: 2.0,
            stall_progress_mm: 3.0,
            escape_s: 1.5,
            escape_factor: 1.5,
            max_stalls: 60,
            keep_poses: true,
            collapsed_spans: Vec::new(),
            glide_mm_s: 20.0,
            rho_per_radius: Some(1.5),
        }
    }
}

impl FlightOptions {
    /// The defaults, fitted to the study (see [`FlightOptions::fitted_to`]).
    pub fn for_study(study: &voyage_core::Study) -> FlightOptions {
        FlightOptions::default().fitted_to(study)
    }

    /// These options with leveling's G toward the patient's posterior (the anterior up in
    /// the view, supine or prone, as a reader expects) and the study's bridged gaps.
    pub fn fitted_to(self, study: &voyage_core::Study) -> FlightOptions {
        FlightOptions {
            dynamics: self.dynamics.with_gravity_along(-study.anterior_local()),
            collapsed_spans: study.collapsed_spans(),
            ..self
        }
    }
}

/// The outcome of one automatic flight.
#[derive(Clone, Debug, Serialize)]
pub struct Flight {
    pub direction: Direction,
    pub reached: bool,
    pub frames: usize,
    pub sim_seconds: f64,
    pub min_wall_distance_mm: f64,
    pub mean_wall_distance_mm: f64,
    /// Mean lumen radius (Ds of the nearest centerline point) along the flight.
    pub mean_local_radius_mm: f64,
    pub stalls: usize,
    pub path_length_mm: f64,
    /// Mean wall time of the physics per frame (ns).
    pub step_ns: f64,
    pub substeps: usize,
    pub clipped_substeps: usize,
    /// Dt left to the goal at the end (mm).
    pub final_dt_mm: f64,
    /// Where the autopilot could not progress for [`STUCK_S`] s and glided on along the
    /// centerline.
    pub rescues: Vec<Rescue>,
    /// Dt (mm) from the goal to the last centerline point the camera fits at, where the
    /// goal's end is narrower than that (0 when it is not): the flight ends there.
    pub short_end_mm: f64,
    /// Mean angle between z_body and the direction of travel (the path's tangent over ±¼ s),
    /// degrees, over frames that moved.
    pub mean_heading_error_deg: f64,
    #[serde(skip)]
    pub poses: Vec<Pose>,
}

/// A place where the flight made no progress for [`STUCK_S`] seconds (or did not move at all
/// for [`WEDGED_S`]) and the autopilot glided on along the centerline.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Rescue {
    /// Simulated time (s).
    pub t: f64,
    /// How long the flight had been without progress (s), or without moving at all when
    /// `wedged`.
    pub stuck_s: f64,
    pub wedged: bool,
    /// Arc length along the centerline, from the end the flight starts at, where the glide
    /// began (mm).
    pub arc_mm: f64,
    /// Where the submarine was (volume-local mm).
    pub position: [f64; 3],
}

impl Rescue {
    /// What held the flight, for the user: "could not move" or "made no progress" (for
    /// `stuck_s` seconds).
    pub fn cause(&self) -> &'static str {
        if self.wedged {
            "could not move"
        } else {
            "made no progress"
        }
    }
}

/// The centerline as the flight sees it: points from the flight's start to its goal.
pub(crate) struct Guide {
    points: Vec<DVec3>,
    radius: Vec<f64>,
    /// Arc length along the centerline from the end the flight starts at (mm).
    arc: Vec<f64>,
}

impl Guide {
    pub(crate) fn new(cl: &Centerline, dir: Direction) -> Self {
        // A canal too narrow to fly (the anal canal) is no part of a flight's way: it starts
        // or ends above it.
        let from = cl
            .arc_mm
            .iter()
            .position(|&a| a >= cl.canal_mm)
            .unwrap_or(0)
            .min(cl.points_mm.len().saturating_sub(2));
        let mut points: Vec<DVec3> = cl.points_mm[from..]
            .iter()
            .map(|p| DVec3::from_array(*p))
            .collect();
        let mut radius = cl.radius_mm[from..].to_vec();
        let mut arc: Vec<f64> = cl.arc_mm[from..].to_vec();
        if dir == Direction::Backward {
            points.reverse();
            radius.reverse();
            arc = arc.iter().rev().map(|a| cl.length_mm - a).collect();
        }
        Guide {
            points,
            radius,
            arc,
        }
    }

    /// The point at arc length `s` (mm from the flight's start) and the index after it.
    fn at_arc(&self, s: f64) -> (DVec3, usize) {
        let i = self
            .arc
            .partition_point(|&a| a < s)
            .clamp(1, self.points.len() - 1);
        let (a, b) = (self.arc[i - 1], self.arc[i]);
        let t = if b > a {
            ((s - a) / (b - a)).clamp(0.0, 1.0)
        } else {
            1.0
        };
        (self.points[i - 1].lerp(self.points[i], t), i)
    }
    /// Arc spans where the lumen's radius is under `roomy_mm`, the goal's end left out
    /// (the flight stops before it).
    fn narrows(&self, roomy_mm: f64) -> Vec<[f64; 2]> {
        let mut spans: Vec<[f64; 2]> = Vec::new();
        let n = self.points.len();
        for i in 0..n.saturating_sub(1) {
            if self.radius[i] >= roomy_mm {
                continue;
            }
            let a = self.arc[i];
            match spans.last_mut() {
                Some(s) if i > 0 && self.radius[i - 1] < roomy_mm => s[1] = a,
                _ => spans.push([a, a]),
            }
        }
        spans
    }
    pub(crate) fn nearest(&self, x: DVec3) -> usize {
        let mut best = (f64::INFINITY, 0);
        for (i, p) in self.points.iter().enumerate() {
            let d = p.distance_squared(x);
            if d < best.0 {
                best = (d, i);
            }
        }
        best.1
    }
    /// Unit direction of the centerline over the next `mm` of arc from point i toward the
    /// goal (over the last `mm` near the goal).
    pub(crate) fn way_on(&self, i: usize, mm: f64) -> DVec3 {
        let last = *self.arc.last().unwrap_or(&0.0);
        let from = self.arc[i].min(last - mm).max(0.0);
        let (a, _) = self.at_arc(from);
        let (b, _) = self.at_arc(from + mm);
        (b - a).try_normalize().unwrap_or_else(|| self.ahead(i))
    }
    /// Which way the view turns at guide point i: toward the centerline [`LOOK_AHEAD_MM`]
    /// on (or [`LOOK_PER_RADIUS`] times the lumen's radius there), as a vector from point i;
    /// near the goal, along the centerline's last stretch.
    fn look_ahead(&self, i: usize) -> DVec3 {
        let reach = LOOK_AHEAD_MM.max(LOOK_PER_RADIUS * self.radius[i]);
        // The mean of the centerline from half to one and a half times the reach: a
        // single point follows the centerline's wiggles between folds, and the view with it.
        let p = LOOK_SPREAD
            .iter()
            .map(|f| self.at_arc(self.arc[i] + f * reach).0)
            .sum::<DVec3>()
            / LOOK_SPREAD.len() as f64;
        let v = p - self.points[i];
        if v.length() >= 0.5 * LOOK_AHEAD_MM {
            v
        } else {
            self.way_on(i, LOOK_AHEAD_MM) * LOOK_AHEAD_MM
        }
    }
    /// Unit direction of the centerline toward the goal at point i.
    fn ahead(&self, i: usize) -> DVec3 {
        let n = self.points.len();
        let a = i.min(n - 1);
        let b = (i + 5).min(n - 1);
        let a = if a == b { a.saturating_sub(5) } else { a };
        (self.points[b] - self.points[a]).normalize_or_zero()
    }
    /// Unit direction from `x` to the centerline point twice the local radius (at least
    /// 10 mm) beyond point i: out of a pocket and on.
    fn toward_ahead(&self, i: usize, x: DVec3) -> DVec3 {
        let reach = (2.0 * self.radius[i]).max(10.0);
        let mut j = i;
        while j + 1 < self.points.len() && self.points[j].distance(self.points[i]) < reach {
            j += 1;
        }
        (self.points[j] - x)
            .try_normalize()
            .unwrap_or_else(|| self.ahead(i))
    }
}

/// The autopilot of a flight, frame by frame: it watches progress toward the goal and,
/// when the submarine stalls in a local minimum of V, pushes it toward the centerline ahead
/// (see the module comment). [`fly`] uses it without a user; the navigator uses it while
/// the flight plays, beside the user's own force.
pub struct Autopilot {
    guide: Guide,
    /// The field's Dt at each guide point (+∞ outside its safe set), read by
    /// [`Autopilot::fit_reach`]; empty until then.
    guide_dt: Vec<f64>,
    stall_window_s: f64,
    stall_progress_mm: f64,
    escape_s: f64,
    escape_factor: f64,
    /// Start of the current stall window: (time, Dt then).
    window_start: (f64, f64),
    escape_until: f64,
    in_a_row: usize,
    near: usize,
    /// The goal counts as reached when Dt is at most this (mm).
    pub reach_mm: f64,
    /// Stalls detected so far.
    pub stalls: usize,
    /// Arc ranges (mm from the flight's start) glided along: bridged gaps with the narrowing
    /// before them, where the wall term of V would hold the submarine back.
    glides: Vec<[f64; 2]>,
    glide_mm_s: f64,
    /// Where the glide has got to (arc mm), while gliding.
    glide_arc: Option<f64>,
    /// The glide that last reached its end: not glided again from inside it.
    glided: Option<usize>,
    up: DVec3,
    /// A glide ends only where the centerline's radius is at least this (mm): the camera is
    /// in the safe set there.
    roomy_mm: f64,
    /// The last progress: (time, Dt then); no progress for [`STUCK_S`] s is a rescue.
    progress: (f64, f64),
    /// The last move: (time, where the submarine was then); none for [`WEDGED_S`] s is a
    /// rescue.
    moved: (f64, DVec3),
    /// Where the autopilot glided on after [`STUCK_S`] s without progress.
    pub rescues: Vec<Rescue>,
    rho_per_radius: Option<f64>,
    /// The direction of the last look (for its spin); None after a glide or a restart.
    look_dir: Option<DVec3>,
}

/// Without [`STUCK_S`] seconds of progress the autopilot glides this far (mm, at least twice
/// the local radius) along the centerline.
const RESCUE_MM: f64 = 20.0;
/// Seconds without progress (Dt falling by `stall_progress_mm`) before a rescue glide.
pub const STUCK_S: f64 = 5.0;
/// Seconds without moving at all ([`WEDGED_MM`]) before a rescue glide: the submarine is
/// wedged where every step would leave the safe set, and the escape pushes cannot free it.
/// On `ct/abdomen-3mm` (not insufflated, a colon 3–5 mm in radius) the forward flight stood
/// still for 5 s in a pocket 6 mm off the centerline and again in a narrow 190 mm on, more
/// than half of its frames.
pub const WEDGED_S: f64 = 1.0;
/// A submarine that has moved less than this (mm) has not moved.
const WEDGED_MM: f64 = 0.1;
/// Centerline stretches whose radius is under the camera's distance from the wall plus this
/// (mm) are glided through: the safe set is too thin there for the field to carry the camera.
pub const NARROW_MARGIN_MM: f64 = 1.0;

/// During the flight the view turns toward the centerline this far (mm of arc) beyond the
/// camera's nearest point ([`Autopilot::look`]) ...
pub const LOOK_AHEAD_MM: f64 = 30.0;
/// ... or this many times the lumen's radius there, whichever is farther: in a chamber wide
/// enough for the camera to stray from the centerline, a nearer point would swing the view
/// across the lumen as the camera passes it.
const LOOK_PER_RADIUS: f64 = 1.5;
/// The look-ahead point is the mean of the centerline at these multiples of the reach.
const LOOK_SPREAD: [f64; 5] = [0.5, 0.75, 1.0, 1.25, 1.5];

/// Where the goal's end is too narrow for the camera, the flight ends within this much Dt
/// (mm) of the last centerline point it fits at ([`Autopilot::fit_reach`]).
pub const GOAL_SLACK_MM: f64 = 5.0;

/// A glide starts this far (mm) before a bridged gap: the lumen narrows toward it and the
/// wall term would stop the submarine there.
const GLIDE_BEFORE_MM: f64 = 25.0;
/// ... and ends this far past it.
const GLIDE_AFTER_MM: f64 = 5.0;

impl Autopilot {
    /// An autopilot for a flight in direction `dir` starting at `x`, where Dt is `dt_now`.
    pub fn new(
        cl: &Centerline,
        dir: Direction,
        opts: &FlightOptions,
        x: DVec3,
        dt_now: f64,
    ) -> Self {
        let guide = Guide::new(cl, dir);
        let near = guide.nearest(x);
        let goal_radius = *guide.radius.last().unwrap_or(&0.0);
        let reach_mm = opts.reach_mm.unwrap_or(goal_radius.max(10.0));
        let roomy_mm = opts.safety.min_wall_mm + NARROW_MARGIN_MM;
        let mut spans: Vec<[f64; 2]> = opts
            .collapsed_spans
            .iter()
            .map(|s| match dir {
                Direction::Forward => [s[0], s[1]],
                Direction::Backward => [cl.length_mm - s[1], cl.length_mm - s[0]],
            })
            .collect();
        spans.extend(guide.narrows(roomy_mm));
        let glides = merged(
            spans
                .into_iter()
                .map(|s| [s[0] - GLIDE_BEFORE_MM, s[1] + GLIDE_AFTER_MM])
                .collect(),
        );
        Autopilot {
            roomy_mm,
            progress: (0.0, dt_now),
            moved: (0.0, x),
            rescues: Vec::new(),
            rho_per_radius: opts.rho_per_radius,
            glides,
            glide_mm_s: opts.glide_mm_s,
            glide_arc: None,
            glided: None,
            up: -opts.dynamics.gravity,
            reach_mm,
            guide,
            guide_dt: Vec::new(),
            stall_window_s: opts.stall_window_s,
            stall_progress_mm: opts.stall_progress_mm,
            escape_s: opts.escape_s,
            escape_factor: opts.escape_factor,
            window_start: (0.0, dt_now),
            escape_until: f64::NEG_INFINITY,
            in_a_row: 0,
            near,
            stalls: 0,
            look_dir: None,
        }
    }

    /// The autopilot's force for the frame starting at time `t` with the submarine at `x`
    /// and Dt = `dt_now`: zero, or an escape push scaled by Ct.
    pub fn input(&mut self, t: f64, dt_now: f64, x: DVec3, ct: f64) -> Input {
        self.note_progress(t, dt_now);
        // Stall: too little progress over the window (not while escaping). Each stall in a
        // row pushes harder.
        if t >= self.escape_until && t - self.window_start.0 >= self.stall_window_s {
            if self.window_start.1 - dt_now < self.stall_progress_mm {
                self.stalls += 1;
                self.in_a_row += 1;
                self.escape_until = t + self.escape_s;
            } else {
                self.in_a_row = 0;
            }
            self.window_start = (t, dt_now);
        }
        let mut input = Input::default();
        if t < self.escape_until {
            let boost = 1.5f64.powi(self.in_a_row.saturating_sub(1).min(8) as i32);
            input.force =
                self.guide.toward_ahead(self.near, x) * self.escape_factor * boost * ct.max(1.0);
        }
        input
    }

    /// Where the centerline's last stretch toward the goal is too narrow for the camera (no
    /// point of it in `field`'s safe set for a camera kept `min_wall_mm` from the wall), the
    /// goal counts as reached once Dt is within [`GOAL_SLACK_MM`] of Dt at the last point
    /// that is: the camera cannot go farther, and would otherwise stall there for good.
    /// Returns how far short of the goal that is (mm of Dt; 0 when the end is roomy). Keeps
    /// the field's Dt along the centerline, where a rescue glide ends ([`Autopilot::glide`]).
    pub fn fit_reach<S: DistanceStore>(
        &mut self,
        field: &PotentialField<S>,
        dir: Direction,
        min_wall_mm: f64,
    ) -> f64 {
        let samples: Vec<_> = self
            .guide
            .points
            .iter()
            .map(|&p| field.sample(p, dir))
            .collect();
        self.guide_dt = samples
            .iter()
            .map(|s| s.dt.unwrap_or(f64::INFINITY))
            .collect();
        let last_safe = samples
            .iter()
            .rev()
            .find_map(|s| (s.lumen_corners == 8 && s.ds >= min_wall_mm).then_some(s.dt));
        match last_safe.flatten() {
            Some(dt) if dt + GOAL_SLACK_MM > self.reach_mm => {
                self.reach_mm = dt + GOAL_SLACK_MM;
                dt
            }
            _ => 0.0,
        }
    }

    /// Restarts the stall watch (the user steered, or the submarine was moved): what happens
    /// next is not the field's doing.
    pub fn restart(&mut self, t: f64, dt_now: f64, x: DVec3) {
        self.watch_from(t, dt_now);
        self.moved = (t, x);
        self.look_dir = None;
        self.near = self.guide.nearest(x);
        self.glide_arc = None;
        self.glided = None;
    }

    /// The view was set from outside (a glide's pose): the next look has no spin to feed.
    pub fn forget_look(&mut self) {
        self.look_dir = None;
    }

    /// Starts the stall watch afresh (a glide is progress, not a stall).
    pub fn watch_from(&mut self, t: f64, dt_now: f64) {
        self.progress = (t, dt_now);
        self.moved.0 = t;
        self.window_start = (t, dt_now);
        self.escape_until = f64::NEG_INFINITY;
        self.in_a_row = 0;
    }

    /// Follows the submarine to `x` after a frame; returns the index of the nearest point of
    /// the guide (the centerline from the flight's start to its goal).
    pub fn moved_to(&mut self, x: DVec3) -> usize {
        self.near = nearest_from(&self.guide, x, self.near);
        self.near
    }

    /// Where the view should turn with the submarine at `x` (after [`Autopilot::moved_to`]),
    /// `dt` seconds after the last look: along the centerline's way on from the nearest
    /// point toward [`LOOK_AHEAD_MM`] ahead, so that the lumen ahead stays near the middle of
    /// the view, and how fast that direction turned since. The submarine turns toward it
    /// with the compass's torque ([`crate::Submarine::look_at`]).
    pub fn look(&mut self, x: DVec3, dt: f64) -> Look {
        let point = x + self.guide.look_ahead(self.near);
        let dir = (point - x).normalize_or_zero();
        let spin = match self.look_dir {
            Some(prev) if dt > 0.0 => {
                prev.cross(dir).normalize_or_zero() * prev.angle_between(dir) / dt
            }
            _ => DVec3::ZERO,
        };
        self.look_dir = Some(dir);
        Look { point, spin }
    }

    fn note_progress(&mut self, t: f64, dt_now: f64) {
        if self.progress.1 - dt_now >= self.stall_progress_mm {
            self.progress = (t, dt_now);
        }
    }

    fn note_move(&mut self, t: f64, x: DVec3) {
        if x.distance(self.moved.1) >= WEDGED_MM {
            self.moved = (t, x);
        }
    }

    /// Whether the flight has made no progress for [`STUCK_S`] seconds at time `t`, or has
    /// not moved for [`WEDGED_S`].
    fn stuck(&self, t: f64) -> bool {
        t - self.progress.0 >= STUCK_S || t - self.moved.0 >= WEDGED_S
    }

    /// The last rescue, if one happened in the `within_s` seconds before `t`.
    pub fn recent_rescue(&self, t: f64, within_s: f64) -> Option<&Rescue> {
        self.rescues.last().filter(|r| t - r.t <= within_s)
    }

    /// In a bridged gap, a narrow (or the stretch before either), or stuck for [`STUCK_S`]
    /// seconds at time `t` (Dt = `dt_now`): the pose `dt` seconds further along the
    /// centerline at the glide speed, looking ahead; None elsewhere. There is no room there
    /// for the field to act in: the flight keeps to the path, slowly.
    pub fn glide(&mut self, x: DVec3, t: f64, dt_now: f64, dt: f64) -> Option<Pose> {
        let i = self.moved_to(x);
        self.note_progress(t, dt_now);
        self.note_move(t, x);
        if self.glide_arc.is_none() && self.stuck(t) {
            self.rescue(t, x, i, dt_now);
        }
        // While gliding, the glide's own arc or the nearest point's, whichever is farther on.
        let here = self
            .glide_arc
            .unwrap_or(self.guide.arc[i])
            .max(self.guide.arc[i]);
        let Some(k) = self.glides.iter().position(|g| g[0] <= here && here < g[1]) else {
            // Past the glide (the field carried the submarine on when a glide pose was
            // refused): it is over.
            self.glide_arc = None;
            return None;
        };
        if self.glided == Some(k) && self.glide_arc.is_none() {
            return None;
        }
        let end = self.roomy_after(self.glides[k][1]);
        let next = (here + self.glide_mm_s * dt).min(end);
        self.glide_arc = (next < end).then_some(next);
        self.glided = Some(k);
        let (p, j) = self.guide.at_arc(next);
        let look = self.guide.look_ahead(j.saturating_sub(1));
        Some(Pose::looking(p, look, self.up))
    }

    /// Starts a rescue glide from guide point `i`, stuck where Dt is `dt_stuck`: at least
    /// [`RESCUE_MM`] (and twice the local radius) along the centerline, and on to where the
    /// field's Dt there is below `dt_stuck` ([`Autopilot::past_the_stall`]).
    fn rescue(&mut self, t: f64, x: DVec3, i: usize, dt_stuck: f64) {
        let from = self.guide.arc[i];
        let least = from + RESCUE_MM.max(2.0 * self.guide.radius[i]);
        let span = [from, self.past_the_stall(least, dt_stuck)];
        let wedged = t - self.progress.0 < STUCK_S;
        self.rescues.push(Rescue {
            t,
            stuck_s: t - if wedged {
                self.moved.0
            } else {
                self.progress.0
            },
            wedged,
            arc_mm: from,
            position: x.to_array(),
        });
        let mut glides = std::mem::take(&mut self.glides);
        glides.push(span);
        self.glides = merged(glides);
        self.glided = None;
        self.glide_arc = Some(from);
        self.progress.0 = t;
        self.moved.0 = t;
    }

    /// The first arc at or after `arc` where the field's Dt on the centerline is below
    /// `dt_stuck` by a stall's progress: from there the field carries the camera on, not
    /// back to where it stuck (`arc` itself where the field was not read). Where a hole
    /// between two touching loops lies beside the way (Dt's shortest way runs through it,
    /// the centerline round the loop), Dt along the centerline rises away from the hole and
    /// falls below the stall's only on the far side: a glide of [`RESCUE_MM`] ended before
    /// that, and the field pulled the camera back to the hole (`ctc/prone-tagged` with
    /// σ 50 HU of noise added: 60 stalls each way at the splenic flexure).
    fn past_the_stall(&self, arc: f64, dt_stuck: f64) -> f64 {
        let g = &self.guide;
        let from = g.arc.partition_point(|&a| a < arc);
        (from..self.guide_dt.len())
            .find(|&j| self.guide_dt[j] < dt_stuck - self.stall_progress_mm)
            .map_or(arc, |j| g.arc[j].max(arc))
    }

    /// The first arc at or after `arc` where the centerline is roomy enough for the camera
    /// (the goal's arc when none is).
    fn roomy_after(&self, arc: f64) -> f64 {
        let g = &self.guide;
        let last = *g.arc.last().unwrap_or(&0.0);
        let from = g.arc.partition_point(|&a| a < arc);
        (from..g.arc.len())
            .find(|&j| g.radius[j] >= self.roomy_mm)
            .map_or(last, |j| g.arc[j])
            .min(last)
    }

    /// ρ of Eq. 2 for the submarine where it is: the options' ρ, at most `rho_per_radius`
    /// times the lumen's radius at the nearest centerline point.
    pub fn rho(&self, p: &PotentialParams) -> f64 {
        match self.rho_per_radius {
            Some(k) => p.rho.min(k * self.guide.radius[self.near]),
            None => p.rho,
        }
    }

    /// Lumen radius at the guide's point `i` (mm).
    pub fn radius(&self, i: usize) -> f64 {
        self.guide.radius[i]
    }
}

/// Spans sorted and overlapping ones joined.
fn merged(mut spans: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    spans.sort_by(|a, b| a[0].total_cmp(&b[0]));
    let mut out: Vec<[f64; 2]> = Vec::new();
    for s in spans {
        match out.last_mut() {
            Some(o) if s[0] <= o[1] => o[1] = o[1].max(s[1]),
            _ => out.push(s),
        }
    }
    out
}

/// Where a flight starts: the first centerline point from the start end that lies in the
/// safe set, looking along the centerline, leveling's up (the patient's anterior) up.
pub fn start_pose<S: DistanceStore>(
    field: &PotentialField<S>,
    cl: &Centerline,
    dir: Direction,
    opts: &FlightOptions,
) -> Result<Pose> {
    if cl.points_mm.len() < 2 {
        return Err(Error::invalid("the centerline is empty"));
    }
    let guide = Guide::new(cl, dir);
    let up = -opts.dynamics.gravity;
    for (i, &p) in guide.points.iter().enumerate() {
        let s = field.sample(p, dir);
        if s.lumen_corners == 8 && s.ds >= opts.safety.min_wall_mm {
            return Ok(Pose::looking(p, guide.ahead(i), up));
        }
    }
    Err(Error::invalid(format!(
        "no centerline point lies in the lumen at least {} mm from the wall",
        opts.safety.min_wall_mm
    )))
}

/// Flies from one end to the other without a user.
pub fn fly<S: DistanceStore>(
    field: &PotentialField<S>,
    cl: &Centerline,
    dir: Direction,
    opts: &FlightOptions,
) -> Result<Flight> {
    let mut run = FlightRun::new(field, cl, dir, opts)?;
    while run.step(field).is_some() {}
    Ok(run.finish(field))
}

/// An automatic flight one frame at a time: [`fly`] runs it to its end, a reading or a
/// window steps it as it goes. The field is passed to each step, the same one each time.
pub struct FlightRun {
    opts: FlightOptions,
    guide: Guide,
    sub: Submarine,
    pilot: Autopilot,
    max_sim: f64,
    frame_dt: f64,
    reach: f64,
    start_dt_mm: f64,
    flight: Flight,
    wall_sum: f64,
    radius_sum: f64,
    physics_ns: u128,
    track: Vec<(DVec3, DVec3)>,
    over: bool,
}

impl FlightRun {
    /// At rest at the start of `dir` ([`start_pose`]); the first step moves.
    pub fn new<S: DistanceStore>(
        field: &PotentialField<S>,
        cl: &Centerline,
        dir: Direction,
        opts: &FlightOptions,
    ) -> Result<FlightRun> {
        let guide = Guide::new(cl, dir);
        let pose = start_pose(field, cl, dir, opts)?;
        let mut sub = Submarine::new(field, pose, opts.safety)?;
        sub.potential = opts.potential;
        sub.dynamics = opts.dynamics;
        sub.modes = opts.modes;
        sub.direction = dir;
        let dt_at = |x: DVec3| field.sample(x, dir).dt.unwrap_or(f64::INFINITY);
        let start_dt_mm = dt_at(sub.state.x);
        let mut pilot = Autopilot::new(cl, dir, opts, sub.state.x, start_dt_mm);
        let short_end_mm = pilot.fit_reach(field, dir, opts.safety.min_wall_mm);
        let mut flight = Flight {
            direction: dir,
            reached: false,
            frames: 0,
            sim_seconds: 0.0,
            min_wall_distance_mm: f64::INFINITY,
            mean_wall_distance_mm: 0.0,
            mean_local_radius_mm: 0.0,
            stalls: 0,
            path_length_mm: 0.0,
            step_ns: 0.0,
            substeps: 0,
            clipped_substeps: 0,
            final_dt_mm: start_dt_mm,
            rescues: Vec::new(),
            short_end_mm,
            mean_heading_error_deg: 0.0,
            poses: Vec::new(),
        };
        if opts.keep_poses {
            flight.poses.push(sub.pose());
        }
        Ok(FlightRun {
            opts: opts.clone(),
            guide,
            max_sim: opts.max_sim_s.unwrap_or(cl.length_mm / 5.0 + 60.0),
            frame_dt: 1.0 / opts.fps,
            reach: pilot.reach_mm,
            start_dt_mm,
            sub,
            pilot,
            flight,
            wall_sum: 0.0,
            radius_sum: 0.0,
            physics_ns: 0,
            track: Vec::new(),
            over: false,
        })
    }

    /// Where the submarine stands now.
    pub fn pose(&self) -> Pose {
        self.sub.pose()
    }

    pub fn direction(&self) -> Direction {
        self.flight.direction
    }

    /// Frames flown so far.
    pub fn frames(&self) -> usize {
        self.flight.frames
    }

    /// Dt (mm along the lumen to the goal) at the start, and at the last frame: how far the
    /// flight has got, for a progress bar.
    pub fn start_dt_mm(&self) -> f64 {
        self.start_dt_mm
    }

    pub fn dt_mm(&self) -> f64 {
        self.flight.final_dt_mm
    }

    /// One frame: the pose after it, or None when the flight is over (the goal reached, the
    /// time spent or too many stalls).
    pub fn step<S: DistanceStore>(&mut self, field: &PotentialField<S>) -> Option<Pose> {
        if self.over {
            return None;
        }
        let dir = self.flight.direction;
        let dt_at = |x: DVec3| field.sample(x, dir).dt.unwrap_or(f64::INFINITY);
        let (sub, pilot, f) = (&mut self.sub, &mut self.pilot, &mut self.flight);
        let t = sub.state.t;
        let dt_now = dt_at(sub.state.x);
        f.final_dt_mm = dt_now;
        if dt_now <= self.reach {
            f.reached = true;
            self.over = true;
            return None;
        }
        if t >= self.max_sim || pilot.stalls >= self.opts.max_stalls {
            self.over = true;
            return None;
        }
        let before = sub.state.x;
        let clock = Instant::now();
        match pilot.glide(sub.state.x, t, dt_now, self.frame_dt) {
            Some(pose) if sub.glide_to(field, pose, self.frame_dt) => {
                pilot.watch_from(sub.state.t, dt_at(sub.state.x));
                pilot.forget_look();
            }
            _ => {
                let input = pilot.input(t, dt_now, sub.state.x, sub.potential.ct);
                sub.potential.rho = pilot.rho(&self.opts.potential);
                sub.look_at = Some(pilot.look(sub.state.x, self.frame_dt));
                let r = sub.step(field, self.frame_dt, &input);
                f.substeps += r.substeps;
                f.clipped_substeps += r.clipped;
            }
        }
        self.physics_ns += clock.elapsed().as_nanos();
        f.frames += 1;

        let x = sub.state.x;
        f.path_length_mm += x.distance(before);
        let ds = field.ds(x);
        f.min_wall_distance_mm = f.min_wall_distance_mm.min(ds);
        self.wall_sum += ds;
        self.radius_sum += self.guide.radius[pilot.moved_to(x)];
        let pose = sub.pose();
        self.track.push((x, pose.z_body()));
        if self.opts.keep_poses {
            f.poses.push(pose);
        }
        Some(pose)
    }

    /// The flight's outcome: where it stopped, with what it met on the way.
    pub fn finish<S: DistanceStore>(mut self, field: &PotentialField<S>) -> Flight {
        let mut f = self.flight;
        f.sim_seconds = self.sub.state.t;
        f.stalls = self.pilot.stalls;
        f.rescues = std::mem::take(&mut self.pilot.rescues);
        if f.frames > 0 {
            f.mean_wall_distance_mm = self.wall_sum / f.frames as f64;
            f.mean_local_radius_mm = self.radius_sum / f.frames as f64;
            f.step_ns = self.physics_ns as f64 / f.frames as f64;
        } else {
            f.min_wall_distance_mm = field.ds(self.sub.state.x);
            f.mean_wall_distance_mm = f.min_wall_distance_mm;
        }
        f.mean_heading_error_deg = mean_heading_error(&self.track, self.opts.fps);
        f
    }
}

/// Mean angle (degrees) between the view z_body and the direction of travel: the path's
/// tangent by central differences over ±¼ s, on frames that moved at least 2 mm in that time.
fn mean_heading_error(track: &[(DVec3, DVec3)], fps: f64) -> f64 {
    let k = (0.25 * fps).round().max(1.0) as usize;
    let (mut sum, mut n) = (0.0, 0usize);
    for i in k..track.len().saturating_sub(k) {
        let travel = track[i + k].0 - track[i - k].0;
        if travel.length() >= 2.0 {
            sum += track[i].1.angle_between(travel).to_degrees();
            n += 1;
        }
    }
    if n == 0 { 0.0 } else { sum / n as f64 }
}

/// The nearest centerline point, searched near the last one first (a flight moves a little
/// per frame), falling back to all points when the local best is far.
pub(crate) fn nearest_from(guide: &Guide, x: DVec3, last: usize) -> usize {
    let n = guide.points.len();
    let lo = last.saturating_sub(40);
    let hi = (last + 40).min(n);
    let (mut best, mut bi) = (f64::INFINITY, last);
    for i in lo..hi {
        let d = guide.points[i].distance_squared(x);
        if d < best {
            best = d;
            bi = i;
        }
    }
    if best.sqrt() > guide.radius[bi].max(5.0) {
        guide.nearest(x)
    } else {
        bi
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A straight centerline along x, 1 mm apart, `n` points long, with radius `r(i)`.
    fn line(n: usize, r: impl Fn(usize) -> f64) -> Centerline {
        Centerline {
            points_mm: (0..n).map(|i| [i as f64, 0.0, 0.0]).collect(),
            arc_mm: (0..n).map(|i| i as f64).collect(),
            radius_mm: (0..n).map(r).collect(),
            length_mm: (n - 1) as f64,
            canal_mm: 0.0,
        }
    }

    #[test]
    fn narrows_are_glided_through_both_ways() {
        // 200 mm, 8 mm wide but 0.9 mm at 100..=104 (the camera keeps 1 mm from the wall).
        let cl = line(201, |i| if (100..=104).contains(&i) { 0.9 } else { 8.0 });
        let opts = FlightOptions::default();
        let ahead = Autopilot::new(&cl, Direction::Forward, &opts, DVec3::ZERO, 200.0);
        assert_eq!(
            ahead.glides,
            vec![[100.0 - GLIDE_BEFORE_MM, 104.0 + GLIDE_AFTER_MM]]
        );
        let back = Autopilot::new(&cl, Direction::Backward, &opts, DVec3::X * 200.0, 200.0);
        assert_eq!(
            back.glides,
            vec![[96.0 - GLIDE_BEFORE_MM, 100.0 + GLIDE_AFTER_MM]]
        );
    }

    #[test]
    fn spans_merge_when_they_overlap() {
        assert_eq!(
            merged(vec![[30.0, 40.0], [0.0, 10.0], [5.0, 20.0]]),
            vec![[0.0, 20.0], [30.0, 40.0]]
        );
    }

    const FRAME: f64 = 1.0 / 30.0;

    /// Holds the submarine about `x` with Dt `dt_now`, rocking 1 mm to and fro as against a
    /// wall, until the autopilot's rescue: its first glide pose and the time.
    fn stuck_until_rescued(pilot: &mut Autopilot, x: DVec3, dt_now: f64) -> (Pose, f64) {
        let mut t = 0.0;
        let mut frame = 0;
        let rocking = |frame: usize| x + DVec3::Y * (frame % 2) as f64;
        while t < STUCK_S - 0.1 {
            assert!(
                pilot.glide(rocking(frame), t, dt_now, FRAME).is_none(),
                "glided at {t} s"
            );
            pilot.input(t, dt_now, rocking(frame), 1.0);
            t += FRAME;
            frame += 1;
        }
        t = STUCK_S + 0.01;
        let pose = pilot
            .glide(rocking(frame), t, dt_now, FRAME)
            .expect("a rescue glide");
        assert_eq!(pilot.rescues.len(), 1);
        assert!(!pilot.rescues[0].wedged && pilot.rescues[0].stuck_s >= STUCK_S);
        (pose, t)
    }

    /// A submarine that does not move at all is wedged: the rescue comes after [`WEDGED_S`],
    /// not [`STUCK_S`], and says so.
    #[test]
    fn a_wedged_submarine_is_rescued_sooner() {
        let cl = line(201, |_| 8.0);
        let opts = FlightOptions::default();
        let x = DVec3::new(50.0, 3.0, 0.0);
        let mut pilot = Autopilot::new(&cl, Direction::Forward, &opts, x, 150.0);
        let mut t = 0.0;
        while pilot.glide(x, t, 150.0, FRAME).is_none() {
            pilot.input(t, 150.0, x, 1.0);
            t += FRAME;
            assert!(t < STUCK_S, "no rescue in {t} s");
        }
        assert!(
            (WEDGED_S..WEDGED_S + 2.0 * FRAME).contains(&t),
            "rescued at {t} s"
        );
        let r = pilot.rescues[0];
        assert!(r.wedged && (r.stuck_s - WEDGED_S).abs() <= 2.0 * FRAME);
        assert_eq!(r.arc_mm, 50.0);
    }

    /// Glides on from `from` at time `t` while the autopilot glides: where it ended, and when.
    fn glide_to_the_end(
        pilot: &mut Autopilot,
        from: DVec3,
        mut t: f64,
        dt_now: f64,
    ) -> (DVec3, f64) {
        let mut last = from;
        while let Some(p) = pilot.glide(last, t, dt_now, FRAME) {
            assert!(p.position.x >= last.x);
            last = p.position;
            t += FRAME;
        }
        (last, t)
    }

    /// Stuck beside a hole between two loops: the camera's Dt (60 mm, by way of the hole) is
    /// what the centerline reaches only 140 mm on, round the loop. The rescue glides that
    /// far, not [`RESCUE_MM`], or the field would pull the camera back to the hole.
    #[test]
    fn a_rescue_glides_on_until_the_field_leads_onward() {
        let cl = line(201, |_| 8.0);
        let opts = FlightOptions::default();
        let x = DVec3::new(50.0, 3.0, 0.0);
        let mut pilot = Autopilot::new(&cl, Direction::Forward, &opts, x, 60.0);
        pilot.guide_dt = (0..=200).map(|i| 200.0 - i as f64).collect();
        let (pose, t) = stuck_until_rescued(&mut pilot, x, 60.0);
        let (last, _) = glide_to_the_end(&mut pilot, pose.position, t, 60.0);
        let onward = 140.0 + opts.stall_progress_mm;
        assert!(
            last.x >= onward - 1.0,
            "glided to {} of the {onward} mm where the field leads on",
            last.x
        );
    }

    #[test]
    fn five_seconds_without_progress_glide_on_and_are_recorded() {
        let cl = line(201, |_| 8.0);
        let opts = FlightOptions::default();
        let x = DVec3::new(50.0, 3.0, 0.0);
        let mut pilot = Autopilot::new(&cl, Direction::Forward, &opts, x, 150.0);
        // Stuck: Dt stays at 150 mm.
        let (pose, t) = stuck_until_rescued(&mut pilot, x, 150.0);
        assert_eq!(pilot.rescues[0].arc_mm, 50.0);
        assert!(pose.position.x > 50.0 && pose.position.y == 0.0);
        // It glides on, along the centerline, at least RESCUE_MM.
        let (last, t) = glide_to_the_end(&mut pilot, pose.position, t, 150.0);
        // (to within a guide point: the glide ends where the nearest point reaches its end)
        assert!(
            last.x >= 50.0 + RESCUE_MM - 1.0,
            "glided only to {}",
            last.x
        );
        assert!(pilot.recent_rescue(t, 10.0).is_some());
        assert_eq!(pilot.rescues.len(), 1);
    }
}
