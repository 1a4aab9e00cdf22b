//! The colon's course in the patient frame: where a place lies along the colon, rectum → cecum.
//!
//! The colon frames the abdomen: from the rectum, low and in the middle of the pelvis, the
//! sigmoid rises to the descending colon on the patient's left, which climbs to the splenic
//! flexure; the transverse colon crosses high to the hepatic flexure on the right; the
//! ascending colon runs down to the cecum, low on the right. A place is put on that course by
//! where it lies in the colon's box in the patient frame (left–right and head–feet, both
//! taken from the direction matrix and the position, never from array order): its *course* is
//! the fraction along the template of the nearest point, 0 at the rectum and 1 at the cecum.
//! Gas compartments are ordered by it, and named by its landmarks: those nearest their ends,
//! and the one halfway along the course between them.

use glam::{DVec2, DVec3};

use crate::Geometry;

/// The colon's segments from the rectum to the cecum.
pub const COLON_SEGMENTS: [&str; 8] = [
    "rectum",
    "sigmoid",
    "descending",
    "splenic flexure",
    "transverse",
    "hepatic flexure",
    "ascending",
    "cecum",
];

/// The template: the segments' landmarks in the colon's box, u from the patient's right (0)
/// to left (1), v from inferior (0) to superior (1), in their order along the colon.
const LANDMARKS: [(&str, f64, f64); 8] = [
    (COLON_SEGMENTS[0], 0.5, 0.0),
    (COLON_SEGMENTS[1], 0.62, 0.22),
    (COLON_SEGMENTS[2], 0.9, 0.5),
    (COLON_SEGMENTS[3], 0.88, 0.95),
    (COLON_SEGMENTS[4], 0.5, 0.85),
    (COLON_SEGMENTS[5], 0.12, 0.92),
    (COLON_SEGMENTS[6], 0.1, 0.55),
    (COLON_SEGMENTS[7], 0.12, 0.28),
];

/// The colon's course within a box in the patient frame (LPS mm).
#[derive(Clone, Debug)]
pub struct Course {
    geom: Geometry,
    lo: DVec3,
    span: DVec3,
    /// Arc length of the template up to each landmark, as a fraction of the whole.
    at: [f64; 8],
}

impl Course {
    /// The course over `colon` (LPS box: the colon's gas, as far as it is known).
    pub fn new(geom: &Geometry, colon: [DVec3; 2]) -> Course {
        let mut at = [0.0; 8];
        for i in 1..8 {
            at[i] = at[i - 1] + landmark(i).distance(landmark(i - 1));
        }
        let total = at[7];
        at.iter_mut().for_each(|a| *a /= total);
        Course {
            geom: geom.clone(),
            lo: colon[0],
            span: (colon[1] - colon[0]).max(DVec3::splat(1.0)),
            at,
        }
    }

    /// (u, v) of a volume-local point: right 0 → left 1, inferior 0 → superior 1.
    fn place(&self, local: DVec3) -> DVec2 {
        let q = self.geom.local_to_patient(local);
        DVec2::new(
            (q.x - self.lo.x) / self.span.x,
            (q.z - self.lo.z) / self.span.z,
        )
    }

    /// Where a volume-local point lies along the colon: 0 at the rectum, 1 at the cecum.
    pub fn along(&self, local: DVec3) -> f64 {
        let p = self.place(local);
        let mut best = (f64::INFINITY, 0.0);
        for i in 1..8 {
            let (a, b) = (landmark(i - 1), landmark(i));
            let s = ((p - a).dot(b - a) / (b - a).length_squared()).clamp(0.0, 1.0);
            let d = p.distance(a + s * (b - a));
            if d < best.0 {
                best = (d, self.at[i - 1] + s * (self.at[i] - self.at[i - 1]));
            }
        }
        best.1
    }

    /// Height of a volume-local point in the patient (LPS z, mm): superior is larger.
    pub fn height(&self, local: DVec3) -> f64 {
        self.geom.local_to_patient(local).z
    }

    /// Landmarks for volume-local points that come in this order along the colon, none
    /// before the `from`th (0 the rectum, 7 the cecum): each point's place, in the colon's
    /// order, nearest in all (the least sum of distances). Named one by one, a sigmoid loop
    /// hanging high in the middle lies as near the ascending colon's landmark as the
    /// sigmoid's, and the segments after it would then be named out of order.
    pub fn places_in_order(&self, points: &[DVec3], from: usize) -> Vec<usize> {
        let from = from.min(7);
        // cost[i][l]: the least sum for points 0..=i with point i at landmark l.
        let mut cost: Vec<[f64; 8]> = Vec::with_capacity(points.len());
        for (i, &q) in points.iter().enumerate() {
            let p = self.place(q);
            let mut row = [f64::INFINITY; 8];
            let mut best_before = f64::INFINITY;
            for l in from..8 {
                if i > 0 {
                    best_before = best_before.min(cost[i - 1][l]);
                }
                let before = if i == 0 { 0.0 } else { best_before };
                row[l] = before + p.distance(landmark(l));
            }
            cost.push(row);
        }
        // Back from the last point: each takes the best landmark no later than the next's.
        let mut out = vec![7; points.len()];
        let mut upto = 7;
        for i in (0..points.len()).rev() {
            let l = (from..=upto)
                .min_by(|&a, &b| cost[i][a].total_cmp(&cost[i][b]))
                .unwrap_or(upto);
            out[i] = l;
            upto = l;
        }
        out
    }

    /// The name of landmark `l` (0 the rectum, 7 the cecum).
    pub fn landmark_name(l: usize) -> &'static str {
        LANDMARKS[l.min(7)].0
    }

    /// Where landmark `name` comes along the colon (0 the rectum, 7 the cecum).
    pub fn order_of(name: &str) -> Option<usize> {
        COLON_SEGMENTS.iter().position(|&s| s == name)
    }

    /// The landmark nearest a fraction `t` of the course (0 at the rectum, 1 at the cecum):
    /// what a stretch of colon passes through between two places, where their midpoint in
    /// space (a U-shaped compartment's centroid lies in the middle of the abdomen, off the
    /// colon) would name the wrong landmark.
    pub fn name_along(&self, t: f64) -> &'static str {
        (0..8)
            .min_by(|&a, &b| (self.at[a] - t).abs().total_cmp(&(self.at[b] - t).abs()))
            .map_or("colon", |i| LANDMARKS[i].0)
    }
}

fn landmark(i: usize) -> DVec2 {
    DVec2::new(LANDMARKS[i].1, LANDMARKS[i].2)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The landmarks come in order along the course, and the course does not depend on how
    /// the volume is stored: a point named by its place in the patient frame gets the same
    /// course in an LPS volume and in one stored with x flipped and axes swapped.
    #[test]
    fn course_runs_rectum_to_cecum_in_the_patient_frame() {
        let box_lps = [DVec3::new(0.0, 0.0, -300.0), DVec3::new(300.0, 200.0, 0.0)];
        let lps_at = |u: f64, v: f64| DVec3::new(300.0 * u, 100.0, -300.0 + 300.0 * v);
        let plain = Geometry::new([300, 200, 300], [1.0; 3], [0.0; 3]).unwrap();
        let mut flipped = Geometry::new([300, 300, 200], [1.0; 3], [300.0, 0.0, -300.0]).unwrap();
        // Stored with i running to the patient's right, j superior and k posterior.
        flipped.direction = [[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]];
        for g in [&plain, &flipped] {
            let c = Course::new(g, box_lps);
            let mut last = -1.0;
            for &(name, u, v) in &LANDMARKS {
                let local = g.patient_to_local(lps_at(u, v));
                let t = c.along(local);
                assert!(t > last, "{name} at {t} after {last}");
                assert_eq!(
                    Course::landmark_name(c.places_in_order(&[local], 0)[0]),
                    name
                );
                last = t;
            }
            assert_eq!(c.name_along(0.0), "rectum");
            assert_eq!(c.name_along(1.0), "cecum");
            assert!(c.along(g.patient_to_local(lps_at(0.5, 0.0))) < 0.01);
            assert!(c.along(g.patient_to_local(lps_at(0.12, 0.28))) > 0.99);
        }
    }
}
