//! What every benchmark shares: its options, the median, the reference Python.

use std::{
    ffi::OsStr,
    path::{Path, PathBuf},
    process::Command,
};

use anyhow::{Context, Result, bail};
use clap::Args;

/// What every benchmark takes.
#[derive(Args, Debug)]
pub struct Common {
    /// Worker threads for voyage (the targets are for one core).
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
    /// Python with the reference libraries (default: bench/.venv from bench/setup.sh).
    #[arg(long)]
    pub python: Option<PathBuf>,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

pub fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The reference Python: the one given, else bench/.venv (made by bench/setup.sh).
pub fn find_python(given: Option<&Path>) -> Result<PathBuf> {
    if let Some(p) = given {
        return Ok(p.to_path_buf());
    }
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../bench/.venv/bin/python");
    if venv.exists() {
        return Ok(venv);
    }
    bail!("no reference Python: run `bash bench/setup.sh` (makes bench/.venv) or pass --python")
}

/// Writes the reference script `name` (its text `script`) into `dir` and runs it on `args`
/// with the reference Python ([`find_python`]), one thread; its standard output.
pub fn run_reference_script(
    python: Option<&Path>,
    dir: &Path,
    (name, script): (&str, &str),
    args: &[&OsStr],
) -> Result<Vec<u8>> {
    let python = find_python(python)?;
    let path = dir.join(name);
    std::fs::write(&path, script).with_context(|| format!("{}: cannot write", path.display()))?;
    let out = Command::new(&python)
        .arg(&path)
        .args(args)
        .env("OMP_NUM_THREADS", "1")
        .output()
        .with_context(|| format!("cannot run {}", python.display()))?;
    if !out.status.success() {
        bail!(
            "{} failed: {}",
            path.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    Ok(out.stdout)
}
