//! An exam's other position (supine and prone): its session waiting beside the one shown,
//! the link between the two, and where the shown camera's place lies in it, frame by frame.
//! No egui here.

use glam::DVec3;
use voyage_core::OFF_WALL_MM;
use voyage_nav::{Direction, Pose};
use voyage_view::{Findings, Link, Marker, centerline_at};

use super::session::Session;
use crate::open::position_of;

/// The position not shown.
pub struct Other {
    pub session: Session,
    /// Its findings, kept while the other position is shown.
    pub findings: Findings,
    /// The shown position's arcs to this one's.
    pub link: Link,
    /// Where the shown camera's place lies here (local mm of this position), this frame.
    pub linked: Option<DVec3>,
}

impl Other {
    /// `other` beside the `shown` session, linked to it.
    pub fn new(shown: &Session, other: Session, findings: Findings) -> Other {
        let link = Link::between(&shown.study, &other.study);
        let mut o = Other {
            session: other,
            findings,
            link,
            linked: None,
        };
        o.follow(shown);
        o
    }

    /// "supine", "prone" ...
    pub fn name(&self) -> &'static str {
        position_of(&self.session.study)
    }

    /// Moves the linked place to where the shown camera is.
    pub fn follow(&mut self, shown: &Session) {
        self.linked = self
            .link
            .show_in(&shown.study, &self.session.study, shown.pose().position);
    }

    /// Where the shown position's marker `m` lies here (off the wall, as a marker's place is
    /// read along the colon).
    pub fn place_of(&self, shown: &Session, m: &Marker) -> Option<DVec3> {
        self.link.show_in(
            &shown.study,
            &self.session.study,
            m.position + m.normal * OFF_WALL_MM,
        )
    }
}

/// The pose in `session` at `x` (its local mm), looking down its colon in its flight's
/// direction from there, anterior up: where a reader switching position stands.
pub fn pose_at(session: &Session, x: DVec3) -> Option<Pose> {
    let study = &session.study;
    let arc = study.arc_at(x)?;
    let (_, t) = centerline_at(study, arc);
    let forward = match session.direction() {
        Direction::Forward => t,
        Direction::Backward => -t,
    };
    Some(Pose::looking(x, forward, study.anterior_local()))
}

/// Swaps the shown position and the other: the other is shown, standing where the shown
/// camera's place lies in it (at the nearest safe spot), and what was shown waits, linked.
/// Returns the session and findings to show, and the new other.
pub fn switch(shown: Session, findings: Findings, other: Other) -> (Session, Findings, Other) {
    let Other {
        session: mut next,
        findings: next_findings,
        link,
        linked,
        ..
    } = other;
    next.set_playing(false);
    if let Some(x) = linked {
        stand_at(&mut next, x);
    }
    let mut waiting = Other {
        session: shown,
        findings,
        link: link.reversed(),
        linked: None,
    };
    waiting.follow(&next);
    (next, next_findings, waiting)
}

/// Puts `session`'s camera at `x`, looking down the colon; where `x` is too near the wall,
/// at the viewing spot for it.
pub fn stand_at(session: &mut Session, x: DVec3) -> bool {
    if let Some(pose) = pose_at(session, x)
        && session.jump_to(pose.position, pose.z_body()).is_ok()
    {
        return true;
    }
    session.move_to_spot(x).is_ok()
}

/// How far back along the colon from a place the camera stands to look at it (mm): the
/// place with the wall around it, as a marker is seen.
const LOOK_BACK_MM: f64 = 20.0;

/// Moves `session`'s camera to look at `x` (a place on or by the wall), anterior up: from
/// the centerline [`LOOK_BACK_MM`] before it in the flight's direction where that is safe,
/// else from the viewing spot for it.
pub fn look_at(session: &mut Session, x: DVec3) -> bool {
    let back = session.study.arc_at(x).map(|arc| {
        let back = match session.direction() {
            Direction::Forward => arc - LOOK_BACK_MM,
            Direction::Backward => arc + LOOK_BACK_MM,
        };
        centerline_at(
            &session.study,
            back.clamp(0.0, session.study.centerline.length_mm),
        )
        .0
    });
    let from_back = back.is_some_and(|c| session.jump_to(c, x - c).is_ok());
    if !from_back && session.move_to_spot(x).is_err() && !stand_at(session, x) {
        return false;
    }
    let at = session.pose().position;
    if at.distance(x) > 1.0 {
        let up = session.study.anterior_local();
        session.place(Pose::looking(at, x - at, up));
    }
    true
}
