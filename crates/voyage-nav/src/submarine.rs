//! The submarine (paper §3.3, Eqs. 3–9): a cylinder of mass 1 pushed down the potential
//! field, by the user's clicks, and by optional torques, integrated with Euler steps.
//!
//! **Safety by construction.** The camera's position X only ever takes values in the safe
//! set S = {X : the eight voxels around X are all lumen, and Ds(X) ≥ `min_wall_mm`}. Every
//! sub-step moves X by less than 0.9 of the finest voxel spacing (and less than a quarter of the
//! local Ds), so it cannot jump over a wall: two cubes of voxel centres that do not touch are
//! at least one voxel apart. If the step's end is outside S, X stops at the farthest safe
//! point of the step (bisection) and the momentum loses its component into the wall. The
//! repulsive term of Eq. 2 keeps the flight off the wall when Cs > 0; this guard holds for
//! any parameters, forces and Δt (Cs = 0 included). `min_wall_mm` is fixed when the
//! submarine is made, since raising it later could leave the camera outside its own set.

use glam::{DMat3, DQuat, DVec3};
use serde::{Deserialize, Serialize};

use crate::{
    camera::Pose,
    potential::{Direction, DistanceStore, PotentialField, PotentialParams},
};
use voyage_core::{Error, Result};

/// A click's push toward the wall starts to fade this far from it (mm): about the stopping
/// distance of the camera at the speed a held click gives it (|F_user| / kf / kf).
pub const EASE_FROM_MM: f64 = 12.0;
/// Nearer the wall than this (mm) a click no longer pushes toward it.
pub const STOP_SHORT_MM: f64 = 4.0;
/// The brake on a pushed camera's motion toward the wall at [`STOP_SHORT_MM`] (1/s, as kf):
/// with the friction it stops the camera within about a millimetre.
const BRAKE_PER_S: f64 = 30.0;
/// The view settles onto the autopilot's look-ahead point in about this time (s): the
/// time constant of a critically damped turn.
const LOOK_TIME_S: f64 = 0.1;

/// Physical constants of the submarine (changeable at any moment).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Dynamics {
    /// kf: friction on the linear momentum (1/s).
    pub kf: f64,
    /// ka: friction on the rotation (Eq. 4).
    pub ka: f64,
    /// Cylinder radius r and length h for the inertia tensor (mm); they shape rotation only.
    pub radius_mm: f64,
    pub length_mm: f64,
    /// |F_user|: the push of a click.
    pub user_force: f64,
    /// G for leveling mode (volume-local; magnitude = strength): y_body turns against it.
    /// A study's flight sets it toward the patient's posterior, whatever the patient's
    /// position ([`crate::FlightOptions::fitted_to`]).
    pub gravity: DVec3,
    /// Caps that keep explicit Euler stable whatever the user does (mm/s, rad/s).
    pub max_speed: f64,
    pub max_spin: f64,
}

impl Dynamics {
    /// The same dynamics with leveling's G along `dir` (volume-local; its strength kept):
    /// leveling keeps the view's up against it.
    pub fn with_gravity_along(self, dir: DVec3) -> Dynamics {
        Dynamics {
            gravity: dir.normalize_or(self.gravity.normalize_or_zero()) * self.gravity.length(),
            ..self
        }
    }
}

impl Default for Dynamics {
    fn default() -> Self {
        Dynamics {
            kf: 6.0,
            ka: 35.0,
            radius_mm: 2.0,
            length_mm: 6.0,
            user_force: 240.0,
            gravity: DVec3::new(0.0, 150.0, 0.0),
            max_speed: 150.0,
            max_spin: 3.0,
        }
    }
}

impl Dynamics {
    /// The principal moments of the cylinder (paper §3.3), body frame.
    pub fn inertia(&self) -> DVec3 {
        let (r, h) = (self.radius_mm, self.length_mm);
        let side = (3.0 * r * r + h * h) / 12.0;
        DVec3::new(side, side, r * r / 2.0)
    }
}

/// Where the view should look: a point, and how fast the direction to it turns (rad/s,
/// world axis), so that the view keeps up with it rather than trailing it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Look {
    pub point: DVec3,
    pub spin: DVec3,
}

/// The optional controls of §3.3.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Modes {
    /// τ = −z_body × ∇V: turn the view down the field; toward [`Submarine::look_at`] when
    /// the autopilot gives a point to look at.
    pub compass: bool,
    /// τ = −y_body × G: keep the up vector against G (the patient's anterior up).
    pub leveling: bool,
    /// Skip Eqs. 5–6: X stays put, the view still turns.
    pub still: bool,
}

/// How safety is kept; fixed when the submarine is made.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Safety {
    /// The camera never comes closer to the wall than this (mm).
    pub min_wall_mm: f64,
    /// A sub-step moves X by at most this fraction of the finest voxel spacing (< 1) ...
    pub voxel_fraction: f64,
    /// ... and at most this fraction of the local Ds.
    pub ds_fraction: f64,
    /// Longest sub-step (s), before the friction limits.
    pub max_substep_s: f64,
    /// A frame advances at most this much simulated time (s): a stalled display does not
    /// make the next frame leap.
    pub max_frame_s: f64,
    /// Sub-steps per frame at most; the frame ends early beyond (reported).
    pub max_substeps: usize,
}

impl Default for Safety {
    fn default() -> Self {
        Safety {
            // The navigable core `prepare` makes is for this distance.
            min_wall_mm: voyage_core::DEFAULT_MIN_WALL_MM,
            voxel_fraction: 0.9,
            ds_fraction: 0.25,
            max_substep_s: 1.0 / 60.0,
            max_frame_s: 0.1,
            max_substeps: 2000,
        }
    }
}

/// The state of Eqs. 3–9. Volume-local mm, seconds.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct State {
    /// X: centre of mass and camera position.
    pub x: DVec3,
    /// P: linear momentum (mass 1, so also the velocity).
    pub p: DVec3,
    /// q: orientation, body → world.
    pub q: DQuat,
    /// L: angular momentum.
    pub l: DVec3,
    /// ω: angular velocity from the last Eq. 8.
    pub omega: DVec3,
    /// Simulated time (s).
    pub t: f64,
}

impl State {
    pub fn at(pose: Pose) -> Self {
        State {
            x: pose.position,
            p: DVec3::ZERO,
            q: pose.orientation,
            l: DVec3::ZERO,
            omega: DVec3::ZERO,
            t: 0.0,
        }
    }
    pub fn pose(&self) -> Pose {
        Pose {
            position: self.x,
            orientation: self.q,
        }
    }
}

/// What the user does during a frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Input {
    /// F_user (Eq. 3): already scaled; see [`Submarine::push_toward`].
    pub force: DVec3,
    /// The user's part of τ_option (Eq. 4): look-around.
    pub torque: DVec3,
}

/// The forces of one Euler step, evaluated at the step's start.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Forces {
    /// ∇V(X).
    pub grad_v: DVec3,
    /// F_user.
    pub user: DVec3,
    /// τ_option: compass + leveling + the user's torque.
    pub option_torque: DVec3,
}

/// One Euler step of Eqs. 5–9 with step `h`, before any safety check. With `still` Eqs. 5–6
/// are skipped. The speed and spin caps of `dy` apply to P and L as they are updated.
pub fn euler_step(s: &State, f: &Forces, dy: &Dynamics, still: bool, h: f64) -> State {
    let r = DMat3::from_quat(s.q);
    let z_body = r.z_axis;
    let (mut p, mut x) = (s.p, s.x);
    if !still {
        // Eq. 3, then Eqs. 5 and 6.
        let dp = -f.grad_v - dy.kf * s.p + f.user;
        p = cap(s.p + dp * h, dy.max_speed);
        x = s.x + p * h;
    }
    // Eq. 4, then Eq. 7.
    let dl = z_body.cross(f.user) - dy.ka * s.omega + f.option_torque;
    let mut l = s.l + dl * h;
    // Eq. 8 with R(t): ω = R I⁻¹ Rᵀ L.
    let inv_i = DMat3::from_diagonal(dy.inertia().recip());
    let world_inv_i = r * inv_i * r.transpose();
    let mut omega = world_inv_i * l;
    if omega.length() > dy.max_spin {
        let k = dy.max_spin / omega.length();
        omega *= k;
        l *= k;
    }
    // Eq. 9: q(t + Δt) = Δq · q(t), Δq = [cos(|ω|Δt/2), sin(|ω|Δt/2) ω/|ω|].
    let q = (delta_q(omega, h) * s.q).normalize();
    State {
        x,
        p,
        q,
        l,
        omega,
        t: s.t + h,
    }
}

/// Δq of Eq. 9: the rotation by |ω|·h about ω.
pub fn delta_q(omega: DVec3, h: f64) -> DQuat {
    let w = omega.length();
    if w * h < 1e-15 {
        return DQuat::IDENTITY;
    }
    let half = 0.5 * w * h;
    let axis = omega / w * half.sin();
    DQuat::from_xyzw(axis.x, axis.y, axis.z, half.cos())
}

fn cap(v: DVec3, max: f64) -> DVec3 {
    let n = v.length();
    if n > max { v * (max / n) } else { v }
}

/// What one frame of physics did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepReport {
    pub substeps: usize,
    /// Sub-steps whose end left the safe set and were cut short at the wall.
    pub clipped: usize,
    /// Simulated seconds advanced.
    pub sim_s: f64,
}

/// The submarine: its state, the parameters the user may change, and its fixed safety.
#[derive(Clone, Debug)]
pub struct Submarine {
    pub state: State,
    pub potential: PotentialParams,
    pub dynamics: Dynamics,
    pub modes: Modes,
    pub direction: Direction,
    /// Where the compass turns the view, when set (the autopilot's look-ahead point on the
    /// centerline, [`crate::Autopilot::look`]); None: down the field, as the paper's
    /// compass. Near a wall or in a wide chamber ∇V is mostly the wall's push, and a view
    /// turned down it faces the wall.
    pub look_at: Option<Look>,
    safety: Safety,
}

impl Submarine {
    /// A submarine at rest at `pose`, which must lie in the safe set.
    pub fn new<S: DistanceStore>(
        field: &PotentialField<S>,
        pose: Pose,
        safety: Safety,
    ) -> Result<Self> {
        if !(safety.min_wall_mm >= 0.0
            && safety.voxel_fraction > 0.0
            && safety.voxel_fraction < 1.0
            && safety.ds_fraction > 0.0)
        {
            return Err(Error::invalid(
                "safety: min_wall_mm ≥ 0, 0 < voxel_fraction < 1 and ds_fraction > 0 are required",
            ));
        }
        let sub = Submarine {
            state: State::at(pose),
            potential: PotentialParams::default(),
            dynamics: Dynamics::default(),
            modes: Modes::default(),
            direction: Direction::Forward,
            look_at: None,
            safety,
        };
        if !sub.is_safe(field, pose.position) {
            return Err(Error::invalid(format!(
                "the start point ({:.1}, {:.1}, {:.1}) mm is not inside the lumen at least {} mm from the wall",
                pose.position.x, pose.position.y, pose.position.z, safety.min_wall_mm
            )));
        }
        Ok(sub)
    }

    pub fn safety(&self) -> &Safety {
        &self.safety
    }

    pub fn pose(&self) -> Pose {
        self.state.pose()
    }

    /// Puts the submarine at `pose`, at rest, `dt` seconds later, if `pose` is inside the
    /// navigable core (else leaves it where it was and returns false): the autopilot's glide
    /// along the centerline through a bridged gap or a narrow, where the field cannot carry
    /// the camera. In a narrow the centerline may run closer to the wall than the safe set
    /// allows; it is still the farthest the camera can keep from it.
    pub fn glide_to<S: DistanceStore>(
        &mut self,
        field: &PotentialField<S>,
        pose: Pose,
        dt: f64,
    ) -> bool {
        if !field.in_lumen_cube(pose.position) {
            return false;
        }
        let t = self.state.t + dt;
        self.state = State::at(pose);
        self.state.t = t;
        true
    }

    /// Whether `x` is in the safe set.
    #[inline]
    pub fn is_safe<S: DistanceStore>(&self, field: &PotentialField<S>, x: DVec3) -> bool {
        let s = field.sample(x, self.direction);
        s.lumen_corners == 8 && s.ds >= self.safety.min_wall_mm
    }

    /// F_user of magnitude |F_user| toward the 3D point seen along `ray` (paper §3.3), eased
    /// off near the wall as an endoscopist stops short of the mucosa: from [`EASE_FROM_MM`]
    /// to [`STOP_SHORT_MM`] its part toward the nearest wall fades to nothing and a brake
    /// against the camera's motion toward the wall grows (the part along the wall stays, so a
    /// push still carries the camera down the lumen). Without it a held click drives the
    /// camera to the safe set's edge, where the view is a blur of mucosa.
    pub fn push_toward<S: DistanceStore>(&self, field: &PotentialField<S>, ray: DVec3) -> DVec3 {
        let force = ray.normalize_or_zero() * self.dynamics.user_force;
        let x = self.state.x;
        let inward = field.ds_gradient(x).normalize_or_zero();
        let near =
            1.0 - ((field.ds(x) - STOP_SHORT_MM) / (EASE_FROM_MM - STOP_SHORT_MM)).clamp(0.0, 1.0);
        let toward_wall = (-force.dot(inward)).max(0.0);
        let closing_speed = (-self.state.p.dot(inward)).max(0.0);
        force + inward * near * (toward_wall + BRAKE_PER_S * closing_speed)
    }

    /// The forces at the current state.
    pub fn forces<S: DistanceStore>(&self, field: &PotentialField<S>, input: &Input) -> Forces {
        let grad_v = field.gradient(self.state.x, &self.potential, self.direction);
        let mut torque = input.torque;
        let r = DMat3::from_quat(self.state.q);
        // The user's push or drag wins while it lasts (its own turn is Eq. 4's z × F_user).
        let user_steers = input.force != DVec3::ZERO || input.torque != DVec3::ZERO;
        if self.modes.compass && !user_steers {
            torque += match self.look_at {
                Some(look) => self.look_torque(r.z_axis, &look),
                None => -r.z_axis.cross(grad_v),
            };
        }
        if self.modes.leveling {
            // The paper's τ_leveling (§3.3) turns y_body toward −G, which also pitches the
            // view toward the horizon; during a flight down the field the compass holds the
            // view down the lumen against it. With no compass to hold it (paused, where V is
            // off, or compass off), or looking at a point (which pitching would pull the view
            // off), only its roll about the view axis acts: a camera put looking down the
            // colon stays so.
            let g = self.dynamics.gravity;
            let mut level = -r.y_axis.cross(g);
            // Upside down, −y × G shrinks as y_body nears G itself, an unstable rest: a view
            // turned over while it looked along G (down a stretch running front to back)
            // stayed over for 78 frames on the real exam. Past 90° it turns at full strength,
            // the way it already turns (any way, exactly over).
            if r.y_axis.dot(g) > 0.0 {
                level = level.try_normalize().unwrap_or(r.z_axis) * g.length();
            }
            let compass_holds =
                self.modes.compass && grad_v != DVec3::ZERO && self.look_at.is_none();
            torque += if compass_holds {
                level
            } else {
                r.z_axis * level.dot(r.z_axis)
            };
        }
        Forces {
            grad_v,
            user: input.force,
            option_torque: torque,
        }
    }

    /// The compass's torque toward `look`: a spring that turns z_body toward the point,
    /// damped critically over [`LOOK_TIME_S`] (the rotation's friction ka, and as much more
    /// as that takes), and the look's own spin fed forward, so that a view following a bend
    /// keeps pace with it instead of trailing by the spin times the damping's time.
    fn look_torque(&self, z_body: DVec3, look: &Look) -> DVec3 {
        let Some(to) = (look.point - self.state.x).try_normalize() else {
            return DVec3::ZERO;
        };
        let i = self.dynamics.inertia().x;
        let stiffness = i / (LOOK_TIME_S * LOOK_TIME_S);
        let damping = 2.0 * i / LOOK_TIME_S;
        let across = |w: DVec3| w - z_body * w.dot(z_body);
        stiffness * z_body.cross(to) + damping * across(look.spin)
            - (damping - self.dynamics.ka).max(0.0) * across(self.state.omega)
    }

    /// Longest sub-step the friction terms allow for a stable explicit Euler step.
    fn max_substep(&self) -> f64 {
        let i_min = self.dynamics.inertia().min_element();
        let mut h = self.safety.max_substep_s;
        if self.dynamics.kf > 0.0 {
            h = h.min(0.5 / self.dynamics.kf);
        }
        if self.dynamics.ka > 0.0 {
            h = h.min(0.5 * i_min / self.dynamics.ka);
        }
        h.max(1e-6)
    }

    /// Advances the simulation by `dt` seconds (at most `max_frame_s`), sub-stepping as
    /// needed. X stays in the safe set after every sub-step.
    pub fn step<S: DistanceStore>(
        &mut self,
        field: &PotentialField<S>,
        dt: f64,
        input: &Input,
    ) -> StepReport {
        let mut report = StepReport::default();
        let mut remaining = if dt.is_finite() {
            dt.clamp(0.0, self.safety.max_frame_s)
        } else {
            0.0
        };
        let h_max = self.max_substep();
        let min_spacing = field.spacing().min_element();
        while remaining > 1e-12 && report.substeps < self.safety.max_substeps {
            let forces = self.forces(field, input);
            let ds = field.ds(self.state.x);
            let max_move = (self.safety.voxel_fraction * min_spacing)
                .min(self.safety.ds_fraction * ds)
                .max(1e-6);
            let mut h = remaining.min(h_max);
            let mut next = euler_step(&self.state, &forces, &self.dynamics, self.modes.still, h);
            while (next.x - self.state.x).length() > max_move && h > 1e-7 {
                h *= 0.5;
                next = euler_step(&self.state, &forces, &self.dynamics, self.modes.still, h);
            }
            if (next.x - self.state.x).length() > max_move {
                // Not even the shortest step stays small (absurd forces): do not move.
                next.x = self.state.x;
                next.p = DVec3::ZERO;
            }
            let leaves = !self.modes.still && !self.is_safe(field, next.x);
            if leaves && !self.is_safe(field, self.state.x) {
                // Left in a narrow by a glide: move only away from the wall, within the core.
                if !(field.in_lumen_cube(next.x) && field.ds(next.x) >= ds) {
                    next.x = self.state.x;
                    next.p = DVec3::ZERO;
                }
            } else if leaves {
                next.x = self.last_safe_point(field, self.state.x, next.x);
                let n = field.ds_gradient(next.x).normalize_or_zero();
                let into = next.p.dot(n);
                next.p = if n == DVec3::ZERO {
                    DVec3::ZERO
                } else if into < 0.0 {
                    next.p - into * n
                } else {
                    next.p
                };
                report.clipped += 1;
            }
            debug_assert!(
                self.is_safe(field, next.x) || next.x == self.state.x || field.ds(next.x) >= ds,
                "the camera left the safe set"
            );
            self.state = next;
            remaining -= h;
            report.sim_s += h;
            report.substeps += 1;
        }
        report
    }

    /// The farthest point of the segment from → to that is safe (`from` is).
    fn last_safe_point<S: DistanceStore>(
        &self,
        field: &PotentialField<S>,
        from: DVec3,
        to: DVec3,
    ) -> DVec3 {
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..16 {
            let mid = 0.5 * (lo + hi);
            if self.is_safe(field, from.lerp(to, mid)) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        from.lerp(to, lo)
    }
}
