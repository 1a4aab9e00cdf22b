//! What every benchmark shares: its options, the median, the reference Python.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
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
