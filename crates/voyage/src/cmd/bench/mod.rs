//! `voyage bench ...`: speed, measured against the reference libraries in the same run.
//!
//! Timings are medians of several repeats after one warm-up, with the page cache warm for
//! both sides, so that the comparison is of decoding work, not of the disk.

use std::path::PathBuf;

use anyhow::Result;
use clap::{Args, Subcommand};

mod common;
mod fly;
mod load;
mod prep;
mod render;

use common::Common;
use load::LoadBench;

#[derive(Args, Debug)]
pub struct BenchArgs {
    #[command(subcommand)]
    what: BenchWhat,
}

#[derive(Subcommand, Debug)]
enum BenchWhat {
    /// Loading: the colon phantom as a 400-slice uncompressed DICOM series and as .nii.gz,
    /// against pydicom+numpy and nibabel.
    Load(LoadBench),
    /// Preprocessing, stage by stage, on the colon phantom and any CT or mask given, against
    /// edt/scipy (Ds), dijkstra3d (Dt), scikit-image and VTK flying edges (surface).
    Prep(PrepBench),
    /// Navigation: a potential-field sample in each storage layout, and the physics per frame
    /// of the automatic flights, on the pipe and colon phantoms and any CT or mask given.
    Fly(FlyBench),
    /// Rendering (paper Table 1): triangles per frame per visibility strategy along both
    /// automatic flights, exactness against drawing everything, CPU and GPU frames/s.
    Render(RenderBench),
}

#[derive(Args, Debug)]
struct RenderBench {
    /// CTs or lumen masks (default, with no input and no --pipe: the colon phantom).
    inputs: Vec<PathBuf>,
    /// Add the pipe phantom.
    #[arg(long)]
    pipe: bool,
    /// Add the full-size colon phantom.
    #[arg(long)]
    colon: bool,
    /// Image size for the CPU renderer and the exactness check (square).
    #[arg(long, default_value_t = 512)]
    size: u32,
    /// Frames taken evenly from each flight.
    #[arg(long, default_value_t = 300)]
    frames: usize,
    /// Random look-around views besides the flights.
    #[arg(long, default_value_t = 100)]
    random: usize,
    /// Leave out the GPU renderer.
    #[arg(long)]
    no_gpu: bool,
    #[command(flatten)]
    common: Common,
}

#[derive(Args, Debug)]
struct FlyBench {
    /// CTs or lumen masks to measure besides the phantoms.
    inputs: Vec<PathBuf>,
    /// Leave out the phantoms.
    #[arg(long)]
    no_phantom: bool,
    /// Samples per layout.
    #[arg(long, default_value_t = 2_000_000)]
    samples: usize,
    #[command(flatten)]
    common: Common,
}

#[derive(Args, Debug)]
struct PrepBench {
    /// CTs or lumen masks to measure besides the full-size colon phantom.
    inputs: Vec<PathBuf>,
    /// Leave out the colon phantom.
    #[arg(long)]
    no_phantom: bool,
    /// Working folder for the masks handed to the reference.
    #[arg(long, default_value = "target/bench-prep")]
    dir: PathBuf,
    /// Timed repeats (after one warm-up).
    #[arg(long, default_value_t = 3)]
    repeats: usize,
    /// Rounds per case, voyage and the references taking turns; ratios are paired within a
    /// round and the median round is reported with the range (a noisy machine drifts over
    /// the minutes one round takes).
    #[arg(long, default_value_t = 1)]
    rounds: usize,
    /// Skip the reference libraries.
    #[arg(long)]
    no_reference: bool,
    #[command(flatten)]
    common: Common,
}

pub fn run(a: &BenchArgs) -> Result<()> {
    match &a.what {
        BenchWhat::Load(l) => load::run(l),
        BenchWhat::Prep(p) => prep::run(
            p.inputs.clone(),
            !p.no_phantom,
            &p.dir,
            p.repeats,
            p.rounds,
            !p.no_reference,
            &p.common,
        ),
        BenchWhat::Fly(f) => fly::run(&f.inputs, !f.no_phantom, f.samples, &f.common),
        BenchWhat::Render(r) => {
            anyhow::ensure!((16..=4096).contains(&r.size), "--size must lie in 16..4096");
            let plan = render::Plan {
                inputs: r.inputs.clone(),
                pipe: r.pipe,
                colon: r.colon,
                size: r.size,
                frames_per_flight: r.frames.max(1),
                random: r.random,
                gpu: !r.no_gpu,
            };
            render::run(&plan, &r.common)
        }
    }
}
