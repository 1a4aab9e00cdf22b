//! `voyage phantom` and `voyage demo`: synthetic scans with ground truth.

use std::{
    path::{Path, PathBuf},
    time::Instant,
};

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use voyage_io::{self as io, LoadOptions, write_atomic};
use voyage_phantom::{self as phantom, ColonOptions, Phantom};

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum Kind {
    /// The paper's looped pipe in a water tank with polyps of 7, 5 and 3 mm (512×512×107).
    Pipe,
    /// A synthetic colon at a real scan's size (≈512×512×400) with folds and polyps.
    Colon,
}

#[derive(Args, Debug)]
pub struct PhantomArgs {
    pub kind: Kind,
    /// The CT, as NIfTI (.nii or .nii.gz), MetaImage (.mha) or NRRD (.nrrd).
    #[arg(long)]
    pub out: PathBuf,
    /// Ground truth JSON (centerline, polyps, source/target ...). The lumen mask is written
    /// beside it as NAME.lumen.nii.gz unless --mask says where.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Ground-truth lumen mask (NIfTI, 1 = colon air).
    #[arg(long)]
    pub mask: Option<PathBuf>,
    /// Also write the CT as a DICOM series into this folder (one file per slice).
    #[arg(long)]
    pub dicom: Option<PathBuf>,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Colon only: a ≈128³ version for fast tests.
    #[arg(long)]
    pub small: bool,
    /// Colon only: pools of tagged fluid with flat air–fluid levels.
    #[arg(long)]
    pub tagged_fluid: bool,
    /// Colon only: lumps of tagged stool on the wall (two in each segment from the rectum to
    /// the ascending colon, one of them mottled with air), colon content to be cleansed.
    #[arg(long)]
    pub tagged_stool: bool,
    /// Colon only: the patient lies prone (face down), so tagged fluid pools anteriorly; a
    /// DICOM series says so (PatientPosition HFP), NIfTI/MetaImage/NRRD cannot.
    #[arg(long)]
    pub prone: bool,
    /// Colon only: a 30 mm stretch of SEGMENT (sigmoid, descending or transverse; without a
    /// value: descending) collapsed to a tissue cord. Repeatable: N collapses leave the gas in
    /// N + 1 pieces.
    #[arg(long, value_name = "SEGMENT", num_args = 0..=1, default_missing_value = "descending",
          value_parser = ["sigmoid", "descending", "transverse"])]
    pub collapsed: Vec<String>,
    /// Colon only: a 40–60 mm stretch of SEGMENT filled to the brim with tagged fluid (no gas,
    /// but lumen). Repeatable.
    #[arg(long, value_name = "SEGMENT", value_parser = ["rectum", "sigmoid", "descending", "transverse", "ascending", "cecum"])]
    pub fluid_filled: Vec<String>,
    /// Colon only: a neck in SEGMENT (sigmoid, descending or transverse), 30 % along: the gas
    /// narrows to a thread 0.9 mm in radius over 10 mm. Repeatable.
    #[arg(long, value_name = "SEGMENT", value_parser = ["sigmoid", "descending", "transverse"])]
    pub narrowed: Vec<String>,
    /// Colon only: small-bowel loops full of oral contrast (no gas), the terminal ileum opening
    /// into a caecal pool of tagged fluid: one bright region with it.
    #[arg(long)]
    pub opacified_small_bowel: bool,
    /// Colon only: the same small-bowel loops full of gas instead (one against the descending
    /// colon, wall to wall; the terminal ileum's gas one with the caecum's through the
    /// ileocaecal valve). Not colon.
    #[arg(long, conflicts_with = "opacified_small_bowel")]
    pub gas_filled_small_bowel: bool,
    /// Colon only, with --gas-filled-small-bowel: the terminal ileum ends short of the
    /// caecum, its gas apart from the colon's (loops of gas beside the colon).
    #[arg(long, requires = "gas_filled_small_bowel")]
    pub closed_ileocaecal_valve: bool,
    /// Colon only: a rectal catheter that joins the colon's gas to the air outside the body
    /// (the body then ends in a perineum just above the first slice).
    #[arg(long)]
    pub rectal_tube: bool,
    /// Colon only, with --rectal-tube: the perineum lies 35 mm lower, and the catheter's way
    /// from the rectum to the anus (about 40 mm) is an anal canal held open by gas round it
    /// (the volume reaches 35 mm further down).
    #[arg(long, requires = "rectal_tube")]
    pub anal_canal: bool,
    /// Colon only, with --rectal-tube: its retention balloon inflated in the lowest rectum
    /// (about 23 ml of air in a 1 mm plastic skin, wall to wall), keeping the rectum's gas
    /// apart from the gas below it and round the catheter.
    #[arg(long, requires = "rectal_tube")]
    pub rectal_balloon: bool,
    /// Colon only: a CT table under the patient on the dependent side (posterior, or anterior
    /// with --prone): a carbon-fibre shell round a foam core, the skin flat on it over a
    /// contact strip with a wedge of outside air beside it.
    #[arg(long)]
    pub table: bool,
    /// Colon only: 4–8 skin folds, thin crevices of outside air on the dependent side and low
    /// in the scan (beside the rectal catheter's exit with --rectal-tube), most closed over by
    /// skin in part of their length: air enclosed in the body in some axial slices.
    #[arg(long)]
    pub skin_folds: bool,
    /// Colon only: 10 gas-filled diverticula, 6 in the sigmoid and 4 in the descending colon:
    /// pouches 5–10 mm across outside the wall, on the side away from gravity, each joined to
    /// the lumen by a neck 2–4 mm across (colon lumen in the truth).
    #[arg(long)]
    pub diverticula: bool,
    /// Colon only: round the CT's values to multiples of HU (after the noise), as a windowed
    /// 8-bit export leaves them.
    #[arg(long, value_name = "HU")]
    pub quantize: Option<f64>,
    /// Colon only: leave out the small-bowel gas pockets.
    #[arg(long)]
    pub no_small_bowel_gas: bool,
    /// Colon only: leave out the lung bases in the top slices.
    #[arg(long)]
    pub no_lungs: bool,
    /// Noise standard deviation in HU.
    #[arg(long, default_value_t = 20.0)]
    pub noise: f64,
    /// Colon only: the same colon supine and prone, as an exam scans it twice: the transverse
    /// colon and sigmoid lie further posterior supine, the fluid moves to the other side, the
    /// descending colon is collapsed supine and the sigmoid prone, stool lies on the dependent
    /// side, polyps stay. Every output name gets -supine and -prone (NAME-supine.nii.gz ...);
    /// --truth's own name holds the link's truth (each supine arc with the prone arc of the
    /// same place); --dicom writes both series into the one folder (HFS and HFP).
    #[arg(long, conflicts_with = "prone")]
    pub pair: bool,
}

pub fn run(a: &PhantomArgs) -> Result<()> {
    writable_format(&a.out)?;
    if a.pair {
        return run_pair(a);
    }
    let t = Instant::now();
    let p = make(a)?;
    eprintln!(
        "made {:?} phantom in {:.2} s",
        a.kind,
        t.elapsed().as_secs_f64()
    );
    write_outputs(
        &p,
        &a.out,
        a.truth.as_deref(),
        a.mask.as_deref(),
        a.dicom.as_deref(),
    )
}

/// `--pair`: both positions, their truths and the link's.
fn run_pair(a: &PhantomArgs) -> Result<()> {
    if !matches!(a.kind, Kind::Colon) {
        anyhow::bail!("--pair makes the colon phantom only");
    }
    let t = Instant::now();
    let pair = phantom::pair::colon_pair(&colon_options(a))?;
    eprintln!(
        "made the colon phantom supine and prone in {:.2} s",
        t.elapsed().as_secs_f64()
    );
    for (p, name, number) in [(&pair.supine, "supine", 1), (&pair.prone, "prone", 2)] {
        let truth = a.truth.as_deref().map(|t| with_suffix(t, name));
        let mask = a.mask.as_deref().map(|m| with_suffix(m, name));
        write_outputs(
            p,
            &with_suffix(&a.out, name),
            truth.as_deref(),
            mask.as_deref(),
            None,
        )?;
        if let Some(dir) = &a.dicom {
            let opts = io::dicom_write::SeriesWriteOptions {
                patient_position: Some(p.truth.position.clone()),
                series_description: format!("voyage phantom {name}"),
                series_number: number,
                uid_seed: a.seed,
                file_prefix: name.into(),
                ..Default::default()
            };
            io::dicom_write::write_series_with(dir, &p.ct, &opts)?;
            eprintln!(
                "wrote {} DICOM slices ({name}) to {}",
                p.ct.dims()[2],
                dir.display()
            );
        }
    }
    if let Some(path) = &a.truth {
        write_atomic(path, |w| {
            w.write_all((pair.truth.to_json() + "\n").as_bytes())
        })?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

/// `dir/name.nii.gz` → `dir/name-supine.nii.gz` (every extension kept).
fn with_suffix(path: &Path, suffix: &str) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let (stem, ext) = match name.find('.') {
        Some(i) if i > 0 => name.split_at(i),
        _ => (name.as_str(), ""),
    };
    path.with_file_name(format!("{stem}-{suffix}{ext}"))
}

fn colon_options(a: &PhantomArgs) -> ColonOptions {
    ColonOptions {
        seed: a.seed,
        small: a.small,
        tagged_fluid: a.tagged_fluid,
        prone: a.prone,
        collapsed: a.collapsed.clone(),
        fluid_filled: a.fluid_filled.clone(),
        narrowed: a.narrowed.clone(),
        opacified_small_bowel: a.opacified_small_bowel,
        gas_filled_small_bowel: a.gas_filled_small_bowel,
        closed_ileocaecal_valve: a.closed_ileocaecal_valve,
        rectal_tube: a.rectal_tube,
        anal_canal: a.anal_canal,
        rectal_balloon: a.rectal_balloon,
        tagged_stool: a.tagged_stool,
        table: a.table,
        skin_folds: a.skin_folds,
        diverticula: a.diverticula,
        small_bowel_gas: !a.no_small_bowel_gas,
        lung_bases: !a.no_lungs,
        noise_hu: a.noise,
        quantize_hu: a.quantize,
        pair_member: false,
    }
}

fn make(a: &PhantomArgs) -> Result<Phantom> {
    Ok(match a.kind {
        Kind::Pipe => phantom::pipe(a.seed)?,
        Kind::Colon => phantom::colon(&colon_options(a))?,
    })
}

/// Writes the CT (any writable format, by extension), the truth JSON with its lumen mask,
/// and optionally a DICOM series, which carries the patient's position (HFS, HFP). Every
/// file is written atomically.
pub fn write_outputs(
    p: &Phantom,
    out: &Path,
    truth: Option<&Path>,
    mask: Option<&Path>,
    dicom: Option<&Path>,
) -> Result<()> {
    save_volume(out, &p.ct)?;
    eprintln!("wrote {}", out.display());
    let mask = mask
        .map(Path::to_path_buf)
        .or_else(|| truth.map(mask_beside));
    if let Some(mask) = &mask {
        io::nifti::save(mask, &p.lumen)?;
        eprintln!("wrote {}", mask.display());
    }
    if let Some(truth) = truth {
        let json = truth_json(p, mask.as_deref())?;
        write_atomic(truth, |w| w.write_all(json.as_bytes()))?;
        eprintln!("wrote {}", truth.display());
    }
    if let Some(dir) = dicom {
        let opts = io::dicom_write::SeriesWriteOptions {
            patient_position: Some(p.truth.position.clone()),
            ..Default::default()
        };
        io::dicom_write::write_series_with(dir, &p.ct, &opts)?;
        eprintln!("wrote {} DICOM slices to {}", p.ct.dims()[2], dir.display());
    }
    Ok(())
}

/// Refuses an output name no writer handles, before minutes go into making the phantom.
fn writable_format(path: &Path) -> Result<io::Format> {
    match io::detect_format(path).ok() {
        Some(f @ (io::Format::MetaImage | io::Format::Nrrd | io::Format::Nifti)) => Ok(f),
        _ => anyhow::bail!(
            "{}: give the output a .nii.gz, .nii, .mha or .nrrd name",
            path.display()
        ),
    }
}

fn save_volume(path: &Path, v: &voyage_core::Volume<i16>) -> Result<()> {
    match writable_format(path).ok() {
        Some(io::Format::MetaImage) => io::metaimage::save(path, v)?,
        Some(io::Format::Nrrd) => io::nrrd::save(path, v)?,
        Some(io::Format::Nifti) => io::nifti::save(path, v)?,
        _ => anyhow::bail!(
            "{}: give the output a .nii.gz, .nii, .mha or .nrrd name",
            path.display()
        ),
    }
    Ok(())
}

/// `colon.json` → `colon.lumen.nii.gz`, beside it.
fn mask_beside(truth: &Path) -> PathBuf {
    let stem = truth
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "truth".into());
    truth.with_file_name(format!("{stem}.lumen.nii.gz"))
}

/// The truth as JSON, with the mask's file name (relative to the JSON) added.
fn truth_json(p: &Phantom, mask: Option<&Path>) -> Result<String> {
    let mut v: serde_json::Value = serde_json::from_str(&p.truth.to_json())?;
    if let (Some(m), Some(obj)) = (mask, v.as_object_mut()) {
        let name = m
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        obj.insert("lumen_mask".into(), name.into());
    }
    Ok(serde_json::to_string_pretty(&v)? + "\n")
}

/// The default job until navigation exists: make the colon phantom, write it, read it back
/// through the loader and describe it.
pub fn demo(out: &Path, small: bool) -> Result<()> {
    std::fs::create_dir_all(out)
        .with_context(|| format!("{}: cannot create folder", out.display()))?;
    let t = Instant::now();
    let p = phantom::colon(&ColonOptions {
        small,
        ..ColonOptions::default()
    })?;
    eprintln!(
        "made the colon phantom in {:.2} s: centerline {:.0} mm, {} polyps, {} folds",
        t.elapsed().as_secs_f64(),
        p.truth.centerline_length_mm,
        p.truth.polyps.len(),
        p.truth.folds
    );
    let ct = out.join("colon.nii.gz");
    write_outputs(&p, &ct, Some(&out.join("colon.json")), None, None)?;
    let loaded = io::load(&ct, &LoadOptions::default())?;
    super::info::Info::new(&ct, &loaded, false).print_text();
    // The preprocessing on what was read back, checked against the phantom's truth.
    let study = voyage_core::prepare(loaded.volume, &Default::default(), |_| {})?;
    let written = voyage_export::study::write_study(&out.join("prep"), &study, Default::default())?;
    let (mut both, mut a, mut b) = (0usize, 0usize, 0usize);
    for (&x, &y) in p.lumen.data().iter().zip(study.segmentation.lumen.data()) {
        both += (x != 0 && y != 0) as usize;
        a += (x != 0) as usize;
        b += (y != 0) as usize;
    }
    let t = &study.timings;
    println!(
        "preprocessed in {:.0} ms after loading:",
        t.total_after_load
    );
    println!(
        "  lumen        {} voxels, Dice {:.4} against the truth",
        study.segmentation.lumen_voxels,
        2.0 * both as f64 / (a + b) as f64
    );
    println!(
        "  centerline   {:.0} mm (truth {:.0} mm)",
        study.centerline.length_mm, p.truth.centerline_length_mm
    );
    println!(
        "  surface      {} triangles in {} cells",
        study.surface.mesh.triangles.len(),
        study.cells.cells.len()
    );
    println!(
        "  exports      {} files in {}",
        written.len(),
        out.join("prep").display()
    );
    Ok(())
}
