//! The user's corrections to the colon found (issue 20, item 7): where the flight starts and
//! ends, and which gas is colon. Each is a point in patient LPS mm; it becomes the
//! `--source`, `--target`, `--seed` or `--exclude` of the next preprocessing run, which the
//! window starts in the background.

use glam::DVec3;
use serde::{Deserialize, Serialize};
use voyage_core::Geometry;

use crate::open::{Frame, PointArgs};

/// One correction, a point in patient LPS mm (script steps and the report use this form:
/// `{"include": [x, y, z]}`, `"reset"`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Correction {
    /// The flight starts here (the rectum end).
    Source([f64; 3]),
    /// The flight ends here (the cecum end).
    Target([f64; 3]),
    /// The gas here is colon.
    Include([f64; 3]),
    /// The gas here is not colon.
    Exclude([f64; 3]),
    /// Back to what was found automatically (the patient position given and the choice of
    /// cleansing stay).
    Reset,
}

/// Two points name the same gas when this close (mm): a segment's anchor, given again.
const SAME_POINT_MM: f64 = 0.5;

impl Correction {
    pub fn describe(&self) -> String {
        let at = |p: &[f64; 3]| format!("LPS ({:.0}, {:.0}, {:.0}) mm", p[0], p[1], p[2]);
        match self {
            Correction::Source(p) => format!("start at {}", at(p)),
            Correction::Target(p) => format!("end at {}", at(p)),
            Correction::Include(p) => format!("gas at {} is colon", at(p)),
            Correction::Exclude(p) => format!("gas at {} is not colon", at(p)),
            Correction::Reset => "corrections cleared".into(),
        }
    }

    /// The points of the next run: `points` (in their own frame, `--coords`) with this
    /// correction, for a volume of geometry `g`. Including gas takes back an exclusion of
    /// the same point, and the other way round.
    pub fn applied_to(&self, points: &PointArgs, g: &Geometry) -> PointArgs {
        let mut out = points.clone();
        let frame = |p: &[f64; 3]| {
            let lps = DVec3::from_array(*p);
            match points.coords {
                Frame::Lps => lps,
                Frame::Local => g.patient_to_local(lps),
            }
        };
        let without =
            |list: &mut Vec<DVec3>, p: DVec3| list.retain(|q| q.distance(p) > SAME_POINT_MM);
        match self {
            Correction::Source(p) => out.source = Some(frame(p)),
            Correction::Target(p) => out.target = Some(frame(p)),
            Correction::Include(p) => {
                let p = frame(p);
                without(&mut out.exclude, p);
                without(&mut out.seed, p);
                out.seed.push(p);
            }
            Correction::Exclude(p) => {
                let p = frame(p);
                without(&mut out.seed, p);
                without(&mut out.exclude, p);
                out.exclude.push(p);
            }
            Correction::Reset => {
                out = PointArgs {
                    position: points.position,
                    coords: points.coords,
                    no_cleanse: points.no_cleanse,
                    ..PointArgs::default()
                }
            }
        }
        out
    }
}

/// How many corrections `points` holds.
pub fn count(points: &PointArgs) -> usize {
    points.seed.len()
        + points.exclude.len()
        + points.source.is_some() as usize
        + points.target.is_some() as usize
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn including_takes_back_an_exclusion_and_reset_keeps_the_position() {
        let g = Geometry::new([4, 4, 4], [1.0; 3], [0.0; 3]).unwrap();
        let p = [1.0, 2.0, 3.0];
        let none = PointArgs {
            position: Some(voyage_core::PatientPosition::Hfp),
            ..PointArgs::default()
        };
        let ex = Correction::Exclude(p).applied_to(&none, &g);
        assert_eq!((ex.exclude.len(), ex.seed.len()), (1, 0));
        let inc = Correction::Include(p).applied_to(&ex, &g);
        assert_eq!((inc.exclude.len(), inc.seed.len()), (0, 1));
        assert_eq!(
            Correction::Include(p).applied_to(&inc, &g).seed.len(),
            1,
            "the same point twice is one seed"
        );
        let s = Correction::Source([5.0, 5.0, 5.0]).applied_to(&inc, &g);
        assert_eq!(count(&s), 2);
        let r = Correction::Reset.applied_to(&s, &g);
        assert_eq!((count(&r), r.position), (0, none.position));
    }

    #[test]
    fn points_go_into_the_frame_the_user_chose() {
        // A volume stored upside down: LPS and local mm differ.
        let mut g = Geometry::new([4, 4, 4], [1.0; 3], [10.0, 20.0, 30.0]).unwrap();
        g.set_direction_mat(glam::DMat3::from_diagonal(DVec3::new(1.0, 1.0, -1.0)));
        let local = PointArgs {
            coords: Frame::Local,
            ..PointArgs::default()
        };
        let p = [11.0, 22.0, 28.0];
        let got = Correction::Target(p).applied_to(&local, &g).target.unwrap();
        assert!(g.local_to_patient(got).distance(DVec3::from_array(p)) < 1e-9);
        let lps = Correction::Target(p)
            .applied_to(&PointArgs::default(), &g)
            .target
            .unwrap();
        assert_eq!(lps, DVec3::from_array(p));
    }

    #[test]
    fn script_form_reads() {
        let c: Vec<Correction> =
            serde_json::from_str(r#"[{"include": [1, 2, 3]}, "reset", {"source": [0, 0, 0]}]"#)
                .unwrap();
        assert_eq!(
            c,
            vec![
                Correction::Include([1.0, 2.0, 3.0]),
                Correction::Reset,
                Correction::Source([0.0; 3])
            ]
        );
    }
}
