//! `voyage bench load`: the colon phantom as a 400-slice uncompressed DICOM series and as
//! .nii.gz, against pydicom+numpy and nibabel.

use std::{
    path::{Path, PathBuf},
    time::Instant,
};

use anyhow::{Context, Result, bail};
use clap::Args;
use serde::Serialize;
use voyage_io::{self as io, LoadOptions};
use voyage_phantom::{self as phantom, ColonOptions};

use super::common::{Common, median, run_reference_script};

#[derive(Args, Debug)]
pub struct LoadBench {
    /// Working folder for the phantom files (kept, reused when already there).
    #[arg(long, default_value = "target/bench-load")]
    dir: PathBuf,
    /// Use the small phantom (quick check of the command itself).
    #[arg(long)]
    small: bool,
    /// Timed repeats per loader (after one warm-up).
    #[arg(long, default_value_t = 5)]
    repeats: usize,
    #[command(flatten)]
    common: Common,
}

#[derive(Serialize)]
struct LoadRow {
    what: &'static str,
    megabytes: f64,
    voyage_ms: f64,
    voyage_mb_s: f64,
    reference: &'static str,
    reference_ms: Option<f64>,
    /// reference time / voyage time: how many times faster voyage is.
    speedup: Option<f64>,
    target_speedup: f64,
}

pub fn run(a: &LoadBench) -> Result<()> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(a.common.threads)
        .build_global()
        .ok();
    let (series, nii) = prepare_load_files(&a.dir, a.small)?;
    let opts = LoadOptions::default();
    let mb = |v: &voyage_core::Volume<i16>| (v.data().len() * 2) as f64 / 1e6;

    let probe = io::load(&series, &opts)?;
    let megabytes = mb(&probe.volume);
    drop(probe);
    let dicom_ms = median_ms(a.repeats, || io::load(&series, &opts).map(drop))?;
    let nii_ms = median_ms(a.repeats, || io::load(&nii, &opts).map(drop))?;

    let reference = run_reference(a, &series, &nii);
    let (ref_dicom, ref_nii) = match &reference {
        Ok(r) => (Some(r.0), Some(r.1)),
        Err(e) => {
            eprintln!("reference not run: {e:#}");
            (None, None)
        }
    };
    let rows = vec![
        row(
            "DICOM series (uncompressed)",
            megabytes,
            dicom_ms,
            "pydicom+numpy",
            ref_dicom,
            3.0,
        ),
        row("NIfTI .nii.gz", megabytes, nii_ms, "nibabel", ref_nii, 1.0),
    ];
    if a.common.json {
        let out = serde_json::json!({"bench": "load", "threads": a.common.threads, "repeats": a.repeats, "rows": rows});
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        print_load_table(&rows, a.common.threads);
    }
    Ok(())
}

fn row(
    what: &'static str,
    megabytes: f64,
    ms: f64,
    reference: &'static str,
    ref_ms: Option<f64>,
    target: f64,
) -> LoadRow {
    LoadRow {
        what,
        megabytes,
        voyage_ms: ms,
        voyage_mb_s: megabytes / (ms / 1e3),
        reference,
        reference_ms: ref_ms,
        speedup: ref_ms.map(|r| r / ms),
        target_speedup: target,
    }
}

fn print_load_table(rows: &[LoadRow], threads: usize) {
    println!("load benchmark ({threads} thread(s), median of repeats, warm cache)");
    println!(
        "{:<30} {:>8} {:>10} {:>10} {:>16} {:>12} {:>9} {:>7}",
        "input", "MB", "voyage ms", "MB/s", "reference", "ref ms", "speedup", "target"
    );
    for r in rows {
        let opt =
            |v: Option<f64>, p: usize| v.map(|x| format!("{x:.p$}")).unwrap_or_else(|| "-".into());
        println!(
            "{:<30} {:>8.1} {:>10.1} {:>10.0} {:>16} {:>12} {:>8}× {:>6.0}×",
            r.what,
            r.megabytes,
            r.voyage_ms,
            r.voyage_mb_s,
            r.reference,
            opt(r.reference_ms, 1),
            opt(r.speedup, 2),
            r.target_speedup
        );
    }
}

/// Writes (once) the colon phantom as a DICOM series and as .nii.gz into `dir`.
fn prepare_load_files(dir: &Path, small: bool) -> Result<(PathBuf, PathBuf)> {
    let tag = if small { "small" } else { "full" };
    let series = dir.join(format!("colon-{tag}-series"));
    let nii = dir.join(format!("colon-{tag}.nii.gz"));
    let stamp = dir.join(format!("colon-{tag}.done"));
    if stamp.exists() && series.is_dir() && nii.is_file() {
        return Ok((series, nii));
    }
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: cannot create folder", dir.display()))?;
    eprintln!("making the colon phantom ({tag}) in {} ...", dir.display());
    let p = phantom::colon(&ColonOptions {
        small,
        ..ColonOptions::default()
    })?;
    if series.exists() {
        std::fs::remove_dir_all(&series)
            .with_context(|| format!("{}: cannot clear", series.display()))?;
    }
    io::dicom_write::write_series(&series, &p.ct)?;
    io::nifti::save(&nii, &p.ct)?;
    std::fs::write(&stamp, b"").with_context(|| format!("{}: cannot write", stamp.display()))?;
    Ok((series, nii))
}

/// Median wall time of `repeats` runs after one warm-up.
fn median_ms(repeats: usize, mut f: impl FnMut() -> voyage_core::Result<()>) -> Result<f64> {
    f()?;
    let mut times = Vec::with_capacity(repeats.max(1));
    for _ in 0..repeats.max(1) {
        let t = Instant::now();
        f()?;
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    Ok(median(&mut times))
}

const LOAD_REFERENCE_PY: &str = include_str!("../../../../../bench/load_reference.py");

/// Runs bench/load_reference.py; returns the median (DICOM ms, NIfTI ms).
fn run_reference(a: &LoadBench, series: &Path, nii: &Path) -> Result<(f64, f64)> {
    // One more repeat than ours: the reference's first run is its warm-up.
    let repeats = (a.repeats + 1).to_string();
    let stdout = run_reference_script(
        a.common.python.as_deref(),
        &a.dir,
        ("load_reference.py", LOAD_REFERENCE_PY),
        &[series.as_os_str(), nii.as_os_str(), repeats.as_ref()],
    )?;
    let v: serde_json::Value =
        serde_json::from_slice(&stdout).context("reference printed no JSON")?;
    let med = |key: &str| -> Result<f64> {
        let mut t: Vec<f64> = v[key]
            .as_array()
            .context("bad reference JSON")?
            .iter()
            .skip(1)
            .filter_map(|x| x.as_f64())
            .map(|s| s * 1e3)
            .collect();
        if t.is_empty() {
            bail!("reference gave no timings for {key}");
        }
        Ok(median(&mut t))
    };
    Ok((med("dicom_s")?, med("nifti_s")?))
}
