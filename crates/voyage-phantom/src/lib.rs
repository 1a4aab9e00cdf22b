//! Synthetic phantoms with exact ground truth: the paper's pipe (§5) and a full colon.
//!
//! A phantom is built from continuous geometry — an axis with a radius ([`axis`]), a wall,
//! haustral folds, polyps, fluid pools ([`tube`]) and an analytic body or water tank
//! around it — and rasterised ([`raster`]) with partial volume (a one-voxel ramp of the
//! signed distance to each surface) and counter-based Gaussian noise. The ground truth
//! follows from the same geometry: the centerline *is* the axis the tube was built around,
//! and the lumen mask is the set of voxels whose centre lies inside the lumen (equivalently,
//! whose noise-free air fraction exceeds ½).
//!
//! The colon's options reproduce what real CT colonography exams do, each with its truth
//! (see [`ColonOptions`]): a prone patient (gravity anterior: the pools move to the other
//! side of the lumen, the levels stay flat); collapsed stretches (the gas in N + 1 pieces);
//! stretches filled with fluid (no gas, but lumen); opacified small-bowel loops (oral
//! contrast, no gas) whose terminal ileum opens into a caecal pool, so that they and the
//! pool are one bright region; a rectal catheter that joins the colon's gas to the air
//! outside the body; a CT table under the patient and skin folds, whose air an axial
//! outside-air flood finds enclosed in the body; grey levels quantised as an 8-bit export
//! leaves them. The true centerline runs on through every gap in the gas. Without the
//! options the phantoms are bit for bit what they were before the options existed (the new
//! choices draw from their own random streams).
//!
//! Everything is deterministic from the seed, whatever the number of threads.
//!
//! Coordinates: volume-local millimetres (x = i·sx, y = j·sy, z = k·sz) with the identity
//! direction, so +x is patient left, +y posterior and +z superior (k = 0 at the feet).

pub mod axis;
pub mod body;
pub mod colon;
pub mod fixtures;
pub mod frame;
pub mod pair;
pub mod pipe;
pub mod polyp;
pub mod posture;
pub mod raster;
pub use voyage_core::rng;
pub mod skin;
pub mod small_bowel;
pub mod truth;
pub mod tube;

pub use colon::{ColonOptions, colon};
pub use pipe::pipe;
pub use truth::{
    CollapsedTruth, DistractorTruth, FilledTruth, FoldTruth, GapTruth, LoopTruth, PolypTruth,
    PoolTruth, RectalTubeTruth, RoiTruth, SegmentTruth, SkinFoldTruth, StoolTruth, TableTruth,
    Truth,
};

use voyage_core::Volume;

/// Values of [`Phantom::labels`]: what each voxel is (by the material at its centre).
pub mod label {
    /// Body tissue, fat, water, tank, the CT table: anything not listed below.
    pub const OTHER: u8 = 0;
    /// Air outside the body (or above and around the water tank), skin folds' air included.
    pub const OUTSIDE_AIR: u8 = 1;
    /// Colon (or pipe) gas: lumen.
    pub const LUMEN_AIR: u8 = 2;
    /// Tagged fluid inside the colon: lumen.
    pub const LUMEN_FLUID: u8 = 3;
    pub const POLYP: u8 = 4;
    /// Colon wall, folds, the collapsed cord, a gas pocket's or small-bowel loop's wall, the
    /// rectal catheter's plastic; the pipe's plastic wall.
    pub const WALL: u8 = 5;
    /// Small-bowel gas: a distractor, not lumen.
    pub const SMALL_BOWEL_GAS: u8 = 6;
    /// Lung base: a distractor, not lumen.
    pub const LUNG: u8 = 7;
    pub const BONE: u8 = 8;
    /// Oral contrast in small-bowel loops: a bright distractor, not lumen.
    pub const SMALL_BOWEL_FLUID: u8 = 9;
    /// Air inside the rectal catheter: joins colon gas and outside air, not lumen.
    pub const RECTAL_TUBE: u8 = 10;
    /// Tagged stool on the colon's wall (its air pockets included): lumen, to be cleansed.
    pub const STOOL: u8 = 11;
    /// Air inside the rectal catheter's retention balloon: the rectum's space it holds open,
    /// lumen.
    pub const RECTAL_BALLOON: u8 = 12;

    /// (value, name) of every label, for the truth JSON.
    pub fn legend() -> Vec<(u8, String)> {
        [
            (OTHER, "other"),
            (OUTSIDE_AIR, "outside_air"),
            (LUMEN_AIR, "lumen_air"),
            (LUMEN_FLUID, "lumen_fluid"),
            (POLYP, "polyp"),
            (WALL, "wall"),
            (SMALL_BOWEL_GAS, "small_bowel_gas"),
            (LUNG, "lung"),
            (BONE, "bone"),
            (SMALL_BOWEL_FLUID, "small_bowel_fluid"),
            (RECTAL_TUBE, "rectal_tube"),
            (STOOL, "tagged_stool"),
            (RECTAL_BALLOON, "rectal_balloon"),
        ]
        .into_iter()
        .map(|(v, n)| (v, n.to_string()))
        .collect()
    }
}

/// A synthetic CT with its ground truth.
#[derive(Clone, Debug)]
pub struct Phantom {
    /// Hounsfield units, with partial volume and noise.
    pub ct: Volume<i16>,
    /// Ground-truth lumen: 1 = colon (or pipe) air or tagged fluid (pools and filled
    /// stretches), 0 = anything else (small-bowel contrast and the catheter's air included).
    pub lumen: Volume<u8>,
    /// What each voxel is; see [`label`].
    pub labels: Volume<u8>,
    pub truth: Truth,
}

/// Number of voxels with each label value.
pub fn label_counts(labels: &Volume<u8>) -> [usize; 256] {
    use rayon::prelude::*;
    labels
        .data()
        .par_chunks(1 << 20)
        .map(|c| {
            let mut h = [0usize; 256];
            c.iter().for_each(|&v| h[v as usize] += 1);
            h
        })
        .reduce(
            || [0usize; 256],
            |mut a, b| {
                a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
                a
            },
        )
}

fn arr(v: glam::DVec3) -> [f64; 3] {
    v.to_array()
}
