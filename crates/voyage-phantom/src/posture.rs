//! How the colon lies in each position of a supine–prone pair: its mobile loops (the
//! transverse colon and the sigmoid's anterior loop, which hang on mesenteries) sag toward
//! the table, so they lie further posterior supine than prone; the fixed parts (rectum,
//! descending and ascending colon) stay. The colon's knots are where it lies prone (the
//! anterior abdominal wall holds the loops there); supine they move. Tagged stool lies on
//! the dependent side in either position.

use glam::DVec3;

use super::axis::Axis;

/// Each stretch that sags supine: its first knot (an index into the colon's `KNOTS`), how
/// far it moves at full size (LPS mm) and the share of that each knot from the first moves,
/// tapering toward the ends so the flexures bend rather than kink. The transverse colon's
/// middle moves 22 mm, the sigmoid's anterior loop 14 mm as a whole (its U-turn kept), as
/// CT colonography pairs show (a few centimetres).
const SUPINE_SAG: &[(usize, [f64; 3], &[f64])] = &[
    (
        29,
        [0.0, 22.0, 0.0],
        &[0.34, 0.64, 0.87, 0.98, 0.98, 0.87, 0.64, 0.34],
    ),
    (
        11,
        [0.0, 14.0, 0.0],
        &[0.3, 0.7, 1.0, 1.0, 1.0, 1.0, 1.0, 0.7, 0.3],
    ),
];

/// Knot `i` of the colon (full-size mm) as it lies supine in a pair.
pub(crate) fn supine_knot(i: usize, p: [f64; 3]) -> [f64; 3] {
    let mut p = DVec3::from_array(p);
    for &(first, shift, weights) in SUPINE_SAG {
        if let Some(w) = i.checked_sub(first).and_then(|k| weights.get(k)) {
            p += DVec3::from_array(shift) * *w;
        }
    }
    p.to_array()
}

/// The angle round the axis at arc `s` (in its frame) of the side gravity pulls toward.
pub(crate) fn dependent_angle(axis: &Axis, s: f64, gravity: DVec3) -> f64 {
    let i = axis.vertex_at(s);
    gravity
        .dot(axis.binormal[i])
        .atan2(gravity.dot(axis.normal[i]))
}

/// Stretches collapsed in one position only: (segment, collapsed supine).
const COLLAPSED_IN_ONE: &[(&str, bool)] = &[("descending", true), ("sigmoid", false)];

/// The segments collapsed in a pair's member (`prone`: which; None: in either), beside those
/// the user gave.
pub(crate) fn pair_collapsed(given: &[String], prone: Option<bool>) -> Vec<String> {
    let mut all = given.to_vec();
    for &(segment, supine) in COLLAPSED_IN_ONE {
        if prone.is_none_or(|p| p != supine) && !all.iter().any(|c| c == segment) {
            all.push(segment.to_string());
        }
    }
    all
}
