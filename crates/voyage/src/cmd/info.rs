//! `voyage info PATH`: what a CT is, without patient identity.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use serde::Serialize;
use voyage_io::{self as io, LoadOptions, Loaded};

#[derive(Args, Debug)]
pub struct InfoArgs {
    /// A DICOM folder or file, NIfTI (.nii, .nii.gz), MetaImage (.mha, .mhd) or NRRD file.
    pub path: PathBuf,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// DICOM: which SeriesInstanceUID to load when the folder holds several.
    #[arg(long)]
    pub series: Option<String>,
    /// Print the series' descriptions (SeriesDescription), which are free text and can hold a
    /// patient's name: left out unless asked for.
    #[arg(long)]
    pub show_descriptions: bool,
}

/// Everything `info` reports. Patient name and ID are never part of it.
#[derive(Serialize)]
pub struct Info {
    pub path: String,
    pub dims: [usize; 3],
    pub spacing_mm: [f64; 3],
    pub origin_lps_mm: [f64; 3],
    pub direction: [[f64; 3]; 3],
    pub orientation: String,
    pub extent_mm: [f64; 3],
    pub hu_min: i16,
    pub hu_max: i16,
    pub megabytes: f64,
    /// DICOM PatientPosition ("HFS", ...); None when the file does not say (NIfTI,
    /// MetaImage, NRRD): `prep` then reads gravity from the air–fluid levels.
    pub position: Option<&'static str>,
    /// Where gravity pulls (LPS unit vector), from the position.
    pub gravity_lps: Option<[f64; 3]>,
    /// An exam scanned in several positions: each position and its series, supine first,
    /// then prone; `prep`, `coverage`, `report` and `view` open the first two together
    /// (empty otherwise).
    pub exam_positions: Vec<ExamPosition>,
    /// The loader's findings, `format` among them (flattened: each key once).
    #[serde(flatten)]
    pub meta: io::Meta,
}

#[derive(Serialize)]
pub struct ExamPosition {
    pub position: &'static str,
    pub describe: &'static str,
    pub series: String,
}

impl Info {
    /// What `info` says of `loaded`; the series' descriptions (free text) only when
    /// `descriptions` is set.
    pub fn new(path: &std::path::Path, loaded: &Loaded, descriptions: bool) -> Info {
        let mut meta = loaded.meta.clone();
        if !descriptions {
            meta.series_description = None;
            meta.other_series
                .iter_mut()
                .for_each(|s| s.description = None);
        }
        let g = loaded.volume.geometry();
        let (lo, hi) = loaded.volume.min_max();
        Info {
            path: path.display().to_string(),
            dims: g.dims,
            spacing_mm: g.spacing,
            origin_lps_mm: g.origin,
            direction: g.direction,
            orientation: g.orientation_code(),
            extent_mm: g.extent_mm().to_array(),
            hu_min: lo,
            hu_max: hi,
            megabytes: (g.len() * 2) as f64 / 1e6,
            position: loaded.meta.position.map(|p| p.code()),
            gravity_lps: loaded.meta.position.map(|p| p.gravity_lps().to_array()),
            exam_positions: Vec::new(),
            meta,
        }
    }

    pub fn print_text(&self) {
        let m = &self.meta;
        println!("{}", self.path);
        println!(
            "  format       {}",
            self.meta
                .format
                .map(|f| format!("{f:?}"))
                .unwrap_or("?".into())
        );
        if let Some(modality) = &m.modality {
            println!("  modality     {modality}");
        }
        if let Some(uid) = &m.series_uid {
            println!("  series       {uid}");
        }
        if let Some(d) = &m.series_description {
            println!("  description  {d}");
        }
        if !m.transfer_syntaxes.is_empty() {
            println!("  transfer     {}", m.transfer_syntaxes.join(", "));
        }
        if m.files > 1 {
            println!("  files        {}", m.files);
        }
        let [nx, ny, nz] = self.dims;
        let [sx, sy, sz] = self.spacing_mm;
        let [ex, ey, ez] = self.extent_mm;
        println!(
            "  dims         {nx} × {ny} × {nz}  ({:.1} MB as i16)",
            self.megabytes
        );
        println!("  spacing      {sx:.4} × {sy:.4} × {sz:.4} mm");
        println!("  extent       {ex:.1} × {ey:.1} × {ez:.1} mm");
        let axes: Vec<char> = self.orientation.chars().collect();
        println!(
            "  orientation  {} (i→{}, j→{}, k→{})",
            self.orientation, axes[0], axes[1], axes[2]
        );
        let [ox, oy, oz] = self.origin_lps_mm;
        println!("  origin       ({ox:.2}, {oy:.2}, {oz:.2}) mm LPS");
        println!("  HU range     {} .. {}", self.hu_min, self.hu_max);
        match self.position {
            Some(p) => println!(
                "  position     {p} (gravity {:?} LPS)",
                self.gravity_lps.unwrap_or_default()
            ),
            None => println!(
                "  position     not in the file (prep reads it from the air–fluid levels, or --position)"
            ),
        }
        for s in &m.other_series {
            println!(
                "  other series {} ({} slices{})",
                s.uid,
                s.slices,
                s.description
                    .as_ref()
                    .map(|d| format!(", {d}"))
                    .unwrap_or_default()
            );
        }
        if self.exam_positions.len() >= 2 {
            let list: Vec<String> = self
                .exam_positions
                .iter()
                .map(|p| format!("{} ({}, series {})", p.describe, p.position, p.series))
                .collect();
            println!(
                "  exam         {} positions: {} (prep, coverage, report and view open the first two together; --series opens one)",
                list.len(),
                list.join("; ")
            );
        }
        for n in &m.notes {
            println!("  note         {n}");
        }
    }
}

pub fn run(a: &InfoArgs) -> Result<()> {
    let opts = LoadOptions {
        series_uid: a.series.clone(),
    };
    let loaded = io::load(&a.path, &opts)?;
    let mut info = Info::new(&a.path, &loaded, a.show_descriptions);
    if a.series.is_none() {
        info.exam_positions = io::positions_in(&a.path)?
            .into_iter()
            .map(|(p, series)| ExamPosition {
                position: p.code(),
                describe: p.describe(),
                series,
            })
            .collect();
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&info)?);
    } else {
        info.print_text();
    }
    Ok(())
}
