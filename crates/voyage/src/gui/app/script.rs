//! Scripted actions (`voyage view --script FILE`): what a user does with mouse and keyboard,
//! written down, so the window can be driven the same way every time (tests, screenshots
//! for the docs, demonstrations). The steps run once the study is ready, one after the
//! other; positions in the endoscopic view are fractions of its width and height from its
//! top-left corner.
//!
//! ```json
//! [
//!   {"play": false},
//!   {"record": "before"},
//!   {"steer": {"at": [0.85, 0.5], "frames": 40}},
//!   {"record": "after"},
//!   {"marker": {"at": [0.5, 0.5], "note": "sessile polyp?"}},
//!   {"measure": {"from": [0.45, 0.5], "to": [0.55, 0.5]}},
//!   {"screenshot": "window.png"},
//!   {"export": "findings"},
//!   {"quit": true}
//! ]
//! ```

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use egui::Vec2;
use glam::DVec3;
use serde::Deserialize;
use voyage_nav::Direction;

use super::{
    App,
    actions::{Action, Fly, Switch, ViewPoint},
};
use crate::gui::corrections::Correction;

#[derive(Clone, Debug, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Step {
    /// Let this many frames pass.
    Wait(u32),
    /// Start or stop the automatic flight.
    Play(bool),
    /// "forward" (rectum → cecum) or "backward".
    Direction(Direction),
    /// Hold the left button on a point of the view for some frames (F_user, paper §3.3).
    Steer {
        at: [f32; 2],
        frames: u32,
    },
    /// Right-drag by (dx, dy) points per frame for some frames (τ_option).
    Look {
        dx: f32,
        dy: f32,
        frames: u32,
    },
    /// Drop a marker on the surface under a point of the view (`kind`: polyp, mass,
    /// diverticulum or other, the default).
    Marker {
        at: [f32; 2],
        note: String,
        #[serde(default)]
        kind: voyage_view::FindingKind,
    },
    /// Size the polyp under a point of the view and mark it.
    Polyp {
        at: [f32; 2],
        #[serde(default)]
        note: String,
    },
    /// Measure between the surface points under two points of the view.
    Measure {
        from: [f32; 2],
        to: [f32; 2],
    },
    /// Jump to a point of the centerline: a fraction of its length from the rectum.
    Jump(f64),
    /// What a left click on a slice at this point (LPS mm) does: move to a viewing spot near
    /// it, looking down the colon.
    MoveTo([f64; 3]),
    /// Put the camera at a pose [x, y, z, qw, qx, qy, qz] (volume-local mm, z_body = view,
    /// y_body = up: the poses of `voyage fly --out`), if it lies inside the colon.
    Pose([f64; 7]),
    /// Fly back to a marker (by label, e.g. "M1").
    GoTo(String),
    /// Show the exam's other position (supine / prone) at the same place, as the O key does.
    SwitchPosition(bool),
    /// Switch to the other position where the link puts a marker (by label), as its "show
    /// in" button does.
    ShowInOther(String),
    /// Run the two-way reading (rectum → cecum, back, then every unseen patch); the script
    /// waits until it is done.
    TwoWay(bool),
    /// Fly to the largest unseen patch.
    NextUnseen(bool),
    /// Turn coverage marking on or off.
    Coverage(bool),
    /// Toggle the close-up volume rendering, the translucency view or the centerline overlay.
    Closeup(bool),
    Translucency(bool),
    Centerline(bool),
    /// Show the cleansed CT on the slices (a tagged exam), and outline what cleansing changed.
    SlicesCleansed(bool),
    SlicesOutline(bool),
    /// Save the camera's pose under a name in the report.
    Record(String),
    /// Save a PNG of the whole window.
    Screenshot(PathBuf),
    /// Export the findings into a folder.
    Export(PathBuf),
    /// Correct the colon found, as the slices' right-click menu and the segment list do
    /// (`{"include": [x, y, z]}`, `{"exclude": ...}`, `{"source": ...}`, `{"target": ...}`,
    /// LPS mm; or `"reset"`), and wait until it has been preprocessed again.
    Correct(Correction),
    /// Close the window.
    Quit(bool),
}

pub struct Script {
    steps: Vec<Step>,
    next: usize,
    /// Frames left of the step being carried out (waits, steering, looking).
    pub busy: u32,
}

impl Script {
    pub fn load(path: &Path) -> anyhow::Result<Script> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read the script", path.display()))?;
        let steps: Vec<Step> = serde_json::from_str(&text)
            .with_context(|| format!("{}: not a list of script steps", path.display()))?;
        Ok(Script {
            steps,
            next: 0,
            busy: 0,
        })
    }

    /// The next step to start, unless the current one still runs.
    pub fn next_step(&mut self) -> Option<Step> {
        if self.busy > 0 {
            self.busy -= 1;
            return None;
        }
        let s = self.steps.get(self.next).cloned();
        self.next += 1;
        s
    }

    pub fn finished(&self) -> bool {
        self.busy == 0 && self.next >= self.steps.len()
    }
}

impl Step {
    /// The action a user would take for this step, for the steps that are one (the rest
    /// are the script's own: waiting, holding the mouse, recording, screenshots).
    fn action(self) -> Option<Action> {
        let when = |on: bool, a: Action| on.then_some(a);
        Some(match self {
            Step::Play(on) => Action::Fly(Fly::Play(on)),
            Step::Direction(d) => Action::Fly(Fly::SetDirection(d)),
            Step::Marker { at, note, kind } => Action::Marker {
                at: ViewPoint::Fraction(at),
                note: Some(note),
                kind: Some(kind),
            },
            Step::Polyp { at, note } => Action::Polyp {
                at: ViewPoint::Fraction(at),
                note: Some(note),
            },
            Step::Measure { from, to } => {
                Action::MeasureBetween(ViewPoint::Fraction(from), ViewPoint::Fraction(to))
            }
            Step::Jump(f) => Action::Jump(f),
            Step::MoveTo(lps) => Action::MoveToLps(DVec3::from_array(lps)),
            Step::Pose(a) => Action::Pose(a),
            Step::GoTo(label) => Action::GoToMarker(label),
            Step::SwitchPosition(on) => return when(on, Action::SwitchPosition),
            Step::ShowInOther(label) => Action::ShowInOther(label),
            Step::TwoWay(on) => return when(on, Action::TwoWayReading),
            Step::NextUnseen(on) => return when(on, Action::NextUnseenPatch),
            Step::Coverage(on) => Action::Set(Switch::Coverage, on),
            Step::Closeup(on) => Action::Set(Switch::Closeup, on),
            Step::Translucency(on) => Action::Set(Switch::Translucency, on),
            Step::Centerline(on) => Action::Set(Switch::Centerline, on),
            Step::SlicesCleansed(on) => Action::Set(Switch::SlicesCleansed, on),
            Step::SlicesOutline(on) => Action::Set(Switch::SlicesOutline, on),
            Step::Export(dir) => Action::Export(Some(dir)),
            Step::Correct(c) => Action::Correct(c),
            Step::Quit(now) => return when(now, Action::Quit),
            Step::Wait(_)
            | Step::Steer { .. }
            | Step::Look { .. }
            | Step::Record(_)
            | Step::Screenshot(_) => return None,
        })
    }
}

impl App {
    /// Starts the script's next step once the one before is done: a user's action goes
    /// through [`App::apply`], as a key or a control would.
    pub(super) fn run_script(&mut self, ctx: &egui::Context) {
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
            step => {
                if let Some(action) = step.action() {
                    self.apply(action, ctx);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_documented_example_parses() {
        let doc = include_str!("script.rs");
        let start = doc.find("//! ```json").unwrap() + "//! ```json".len();
        let end = start + doc[start..].find("//! ```").unwrap();
        let json: String = doc[start..end]
            .lines()
            .map(|l| l.trim_start_matches("//!"))
            .collect::<Vec<_>>()
            .join("\n");
        let steps: Vec<Step> = serde_json::from_str(&json).unwrap();
        assert_eq!(steps.len(), 9);
        assert!(matches!(steps[2], Step::Steer { frames: 40, .. }));
    }

    #[test]
    fn unknown_steps_are_refused() {
        assert!(serde_json::from_str::<Vec<Step>>(r#"[{"fly_to_moon": 1}]"#).is_err());
    }
}
