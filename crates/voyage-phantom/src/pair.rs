//! One colon scanned twice, supine and prone, with the truth that links the two: where each
//! place along one position's centerline lies along the other's.
//!
//! Between the two (see `posture.rs`): the transverse colon and the sigmoid's anterior loop
//! lie centimetres further posterior supine than prone; the tagged fluid moves to the other side of the
//! lumen; a stretch of the descending colon is collapsed supine and open prone, one of the
//! sigmoid open supine and collapsed prone; stool lumps lie on the dependent side, so they
//! roll round the lumen, while polyps keep their place on the wall.

use serde::{Deserialize, Serialize};

use super::{
    Phantom,
    colon::{ColonOptions, colon, pair_axes},
};
use voyage_core::{Error, Result};

/// The two positions and their link.
#[derive(Clone, Debug)]
pub struct Pair {
    pub supine: Phantom,
    pub prone: Phantom,
    pub truth: PairTruth,
}

/// The link's truth, serialisable to JSON (`pair.json` beside the two positions' truths).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct PairTruth {
    pub seed: u64,
    /// How to read the lists.
    pub note: String,
    /// Arc lengths along the supine centerline (every mm) and, at the same index, the arc of
    /// the same place of the colon along the prone centerline. Both increase.
    pub supine_arc_mm: Vec<f64>,
    pub prone_arc_mm: Vec<f64>,
}

const NOTE: &str = "supine_arc_mm[i] and prone_arc_mm[i] are the same place of the colon \
(the same point of its wall's axis) along each position's true centerline (the truths' \
centerline_arc_mm). Polyps are listed in the same order in both truths and did not move on \
the wall; stool lumps are listed in the same order and lie on each position's dependent side.";

impl PairTruth {
    /// The prone arc of the place at supine arc `s` (linear between the samples).
    pub fn prone_arc(&self, s: f64) -> f64 {
        interpolate(&self.supine_arc_mm, &self.prone_arc_mm, s)
    }

    /// The supine arc of the place at prone arc `s`.
    pub fn supine_arc(&self, s: f64) -> f64 {
        interpolate(&self.prone_arc_mm, &self.supine_arc_mm, s)
    }

    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_else(|e| {
            serde_json::json!({ "error": format!("cannot serialise pair truth: {e}") }).to_string()
        })
    }

    pub fn from_json(text: &str) -> Result<PairTruth> {
        serde_json::from_str(text).map_err(|e| Error::invalid(format!("pair truth JSON: {e}")))
    }
}

/// `ys` at `x` along increasing `xs`, linear between samples, held beyond the ends.
fn interpolate(xs: &[f64], ys: &[f64], x: f64) -> f64 {
    let i = xs
        .partition_point(|&a| a <= x)
        .clamp(1, xs.len().max(2) - 1);
    let (x0, x1) = (xs[i - 1], xs[i]);
    let t = if x1 > x0 {
        ((x - x0) / (x1 - x0)).clamp(0.0, 1.0)
    } else {
        0.0
    };
    ys[i - 1] + (ys[i] - ys[i - 1]) * t
}

/// Makes the colon of `opts` supine and prone (its `prone` and `pair_member` are set here;
/// each position collapses its own stretch beside `opts.collapsed`).
pub fn colon_pair(opts: &ColonOptions) -> Result<Pair> {
    let member = |prone: bool| ColonOptions {
        prone,
        pair_member: true,
        ..opts.clone()
    };
    let (supine, prone) = rayon::join(|| colon(&member(false)), || colon(&member(true)));
    let (supine, prone) = (supine?, prone?);
    let (a, b) = pair_axes(opts.small)?;
    let n = a.length.floor() as usize;
    let supine_arc_mm: Vec<f64> = (0..=n).map(|i| (i as f64).min(a.length)).collect();
    let prone_arc_mm = supine_arc_mm.iter().map(|&s| a.arc_on(&b, s)).collect();
    Ok(Pair {
        supine,
        prone,
        truth: PairTruth {
            seed: opts.seed,
            note: NOTE.into(),
            supine_arc_mm,
            prone_arc_mm,
        },
    })
}
