//! Opening a study, one way for every command and the window: the input and the user's
//! choices ([`InputArgs`], [`PointArgs`]) loaded ([`voyage_io::load`]) and preprocessed
//! ([`voyage_core::prepare`]), the loader's doubts heading the study's warnings.

use std::{path::PathBuf, time::Instant};

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use glam::DVec3;
use voyage_core::{
    Geometry, PatientPosition, PositionSource, PrepOptions, Stage, Study, Volume, prepare,
};
use voyage_export::{Exam, HandCorrection};
use voyage_io::{self as io, LoadOptions};

#[derive(Clone, Copy, Debug, Default, ValueEnum)]
pub enum Frame {
    /// DICOM patient coordinates (LPS mm), as viewers show them.
    #[default]
    Lps,
    /// Volume-local mm (x = i·sx, y = j·sy, z = k·sz), as the phantoms' truth files give them.
    Local,
}

/// The input and the preprocessing choices every command that runs `prep` shares.
#[derive(Args, Debug, Clone)]
pub struct InputArgs {
    /// A CT (DICOM folder or file, NIfTI, MetaImage, NRRD) or a lumen mask (0/1 labels).
    pub input: PathBuf,
    /// Treat the input as a lumen mask, every non-zero label lumen (default: detected when it
    /// holds 0 and one other value, as 0/1 or 0/255; labels 0/1/2... need it).
    #[arg(long)]
    pub mask: bool,
    #[command(flatten)]
    pub points: PointArgs,
    /// DICOM: which series to load when the folder holds several.
    #[arg(long)]
    pub series: Option<String>,
}

/// A DICOM PatientPosition code, any case.
fn parse_position(s: &str) -> Result<PatientPosition, String> {
    PatientPosition::parse(s)
        .ok_or_else(|| format!("{s}: expected one of HFS, HFP, FFS, FFP, HFDR, HFDL, FFDR, FFDL"))
}

/// Corrections to the automatic choices: which gas is colon, where the flight starts and
/// ends, how the patient lay, whether the colon's tagged fluid is cleansed.
#[derive(Args, Debug, Clone, Default)]
pub struct PointArgs {
    /// A point in gas that is colon (mm, see --coords): its gas joins the colon. It does not
    /// move the start; --source does. Repeat it for several segments (`prep --json` lists
    /// each segment with a point in it, `anchor_lps_mm`).
    #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
    pub seed: Vec<DVec3>,
    /// A point in gas that is not colon (mm, see --coords): its gas is left out, even when it
    /// is the lowest (the rectum is then the lowest of the rest). Repeatable.
    #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
    pub exclude: Vec<DVec3>,
    /// The rectum end of the flight (mm, see --coords).
    #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
    pub source: Option<DVec3>,
    /// The cecum end of the flight (mm, see --coords).
    #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
    pub target: Option<DVec3>,
    /// The coordinate frame of --seed, --source and --target.
    #[arg(long, value_enum, default_value_t = Frame::Lps)]
    pub coords: Frame,
    /// How the patient lay, as a DICOM PatientPosition code (HFS, HFP, FFS, FFP, HFDR, HFDL,
    /// FFDR, FFDL), overriding the file and the air–fluid levels: decides on which side fluid
    /// lies and which way is up in the view.
    #[arg(long, value_parser = parse_position)]
    pub position: Option<PatientPosition>,
    /// Keep the colon's tagged fluid: no electronic cleansing (on by default where the
    /// colon holds tagged fluid; the surface is then cut at the fluid's edge).
    #[arg(long)]
    pub no_cleanse: bool,
}

impl PointArgs {
    /// Puts the choices into `opts` for a volume of geometry `g` whose loader found `meta`.
    pub fn apply(&self, g: &Geometry, meta: &io::Meta, opts: &mut PrepOptions) {
        let to_local = |p: DVec3| match self.coords {
            Frame::Lps => g.patient_to_local(p),
            Frame::Local => p,
        };
        opts.segment.seeds_mm = self.seed.iter().map(|&p| to_local(p)).collect();
        opts.segment.exclude_mm = self.exclude.iter().map(|&p| to_local(p)).collect();
        opts.centerline.source_mm = self.source.map(to_local);
        opts.centerline.target_mm = self.target.map(to_local);
        opts.segment.position = match (self.position, meta.position) {
            (Some(p), _) => Some((p, PositionSource::Given)),
            (None, Some(p)) => Some((p, PositionSource::Dicom)),
            (None, None) => None,
        };
        if self.no_cleanse {
            opts.cleanse = None;
        }
    }

    /// The corrections made by hand, in patient LPS, for the report: ends, then gas taken in,
    /// then gas left out.
    pub fn by_hand(&self, g: &Geometry) -> Vec<HandCorrection> {
        let lps = |p: DVec3| {
            match self.coords {
                Frame::Lps => p,
                Frame::Local => g.local_to_patient(p),
            }
            .to_array()
        };
        let ends = [
            (self.source, "start of the flight placed"),
            (self.target, "end of the flight placed"),
        ];
        let ends = ends.into_iter().filter_map(|(p, what)| Some((p?, what)));
        let gas = (self.seed.iter().map(|&p| (p, "gas taken in as colon"))).chain(
            self.exclude
                .iter()
                .map(|&p| (p, "gas left out of the colon")),
        );
        ends.chain(gas)
            .map(|(p, what)| HandCorrection {
                what,
                lps_mm: lps(p),
            })
            .collect()
    }
}

/// What the report says of an exam named `name` (its file name), of geometry `g`, whose
/// loader found `meta`, corrected by `points`: the series (never its free-text description,
/// which can hold a name) and the date when the file has them.
pub fn exam_of(name: &str, meta: &io::Meta, points: &PointArgs, g: &Geometry) -> Exam {
    let series = match meta.format {
        Some(io::Format::Dicom) => {
            let number = meta
                .series_number
                .map_or(String::new(), |n| format!(" {n}"));
            Some(format!(
                "{} series{number}, {} slices (DICOM)",
                meta.modality.as_deref().unwrap_or("image"),
                meta.files
            ))
        }
        Some(io::Format::Nifti) => Some("NIfTI file".into()),
        Some(io::Format::MetaImage) => Some("MetaImage file".into()),
        Some(io::Format::Nrrd) => Some("NRRD file".into()),
        None => None,
    };
    Exam {
        name: name.to_string(),
        series,
        date: meta.exam_date.clone(),
        by_hand: points.by_hand(g),
    }
}

pub fn parse_point(s: &str) -> Result<DVec3, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{s}: {e}"))?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(DVec3::new(x, y, z)),
        _ => Err(format!("{s}: expected three numbers x,y,z")),
    }
}

/// A study ready for navigation, and what it cost to load.
pub struct Prepared {
    /// In the study storage: its local mm are read with `study.ct.geometry()`.
    pub study: Study,
    /// What the report says of the exam.
    pub exam: Exam,
    /// The DICOM series loaded, when the file says.
    pub series_uid: Option<String>,
    pub load_ms: f64,
}

/// How far opening has got: step `step` of [`OPEN_STEPS`] (reading, then the
/// preprocessing's stages), doing `what`.
#[derive(Clone, Copy, Debug)]
pub struct Opening<'a> {
    pub step: usize,
    pub what: &'a str,
}

/// Steps [`open_study`] tells: reading, then each preprocessing stage.
pub const OPEN_STEPS: usize = Stage::ALL.len() + 1;

/// Loads the input and runs the whole preprocessing, with the navigable core for a camera
/// `nav_min_wall_mm` from the wall (None: made when navigation first asks).
pub fn open_study(
    a: &InputArgs,
    nav_min_wall_mm: Option<f64>,
    mut progress: impl FnMut(Opening),
) -> Result<Prepared> {
    progress(Opening {
        step: 0,
        what: "reading",
    });
    let t0 = Instant::now();
    let loaded = io::load(
        &a.input,
        &LoadOptions {
            series_uid: a.series.clone(),
        },
    )?;
    let load_ms = t0.elapsed().as_secs_f64() * 1e3;
    let choices = Choices {
        points: &a.points,
        mask: a.mask,
        nav_min_wall_mm,
    };
    let name = a.input.display().to_string();
    // The file name only: folders of DICOM files are often named after the patient, and the
    // last component is what the user chose to open.
    let file_name = a
        .input
        .file_name()
        .map_or_else(|| name.clone(), |n| n.to_string_lossy().into_owned());
    let exam = exam_of(
        &file_name,
        &loaded.meta,
        &a.points,
        loaded.volume.geometry(),
    );
    let series_uid = loaded.meta.series_uid.clone();
    let study = prepare_volume(loaded.volume, loaded.meta, &choices, &name, progress)?;
    Ok(Prepared {
        study,
        exam,
        series_uid,
        load_ms,
    })
}

/// The series to open for each position the exam at `a.input` was scanned in: the supine
/// and the prone (else the first two positions) when a DICOM folder holds CT series of
/// different patient positions and `--series` names none; else one, None (the input as the
/// user gave it). Positions beyond two are left, said on stderr with their series.
/// Points (`--seed`, `--exclude`, `--source`, `--target`) and `--position` are of one
/// position: with two they are refused, asking for `--series`.
pub fn exam_positions(a: &InputArgs) -> Result<Vec<Option<String>>> {
    if a.series.is_some() {
        return Ok(vec![a.series.clone()]);
    }
    let positions = io::positions_in(&a.input)?;
    if positions.len() < 2 {
        return Ok(vec![None]);
    }
    let p = &a.points;
    let given = !p.seed.is_empty()
        || !p.exclude.is_empty()
        || p.source.is_some()
        || p.target.is_some()
        || p.position.is_some();
    if given {
        let list: Vec<String> = positions
            .iter()
            .map(|(pos, uid)| format!("{} {uid}", pos.code()))
            .collect();
        bail!(
            "{}: the folder holds the exam in {} positions ({}): --seed, --exclude, --source, --target and --position are of one of them; give --series UID with them",
            a.input.display(),
            positions.len(),
            list.join(", ")
        );
    }
    for (pos, uid) in positions.iter().skip(2) {
        eprintln!(
            "note: {}: the exam's {} series ({}) is not opened with the first two positions; --series {uid} opens it",
            a.input.display(),
            pos.describe(),
            pos.code()
        );
    }
    Ok(positions
        .into_iter()
        .take(2)
        .map(|(_, uid)| Some(uid))
        .collect())
}

/// Opens every position of the exam (see [`exam_positions`]), one after another (each
/// peaks at the memory of one): `progress` hears which position (from 0, of how many) and
/// how far it has got.
pub fn open_exam(
    a: &InputArgs,
    nav_min_wall_mm: Option<f64>,
    mut progress: impl FnMut(usize, usize, Opening),
) -> Result<Vec<Prepared>> {
    let series = exam_positions(a)?;
    let n = series.len();
    series
        .into_iter()
        .enumerate()
        .map(|(i, uid)| {
            let one = InputArgs {
                series: uid.clone(),
                ..a.clone()
            };
            let mut p = open_study(&one, nav_min_wall_mm, |o| progress(i, n, o)).with_context(
                || match &uid {
                    Some(uid) if n > 1 => format!("the exam's series {uid}"),
                    _ => "the exam".to_string(),
                },
            )?;
            if n > 1 {
                p.exam.name = format!("{} ({})", p.exam.name, position_of(&p.study));
            }
            Ok(p)
        })
        .collect()
}

/// How the patient lay for `study`, as a short name that also names its folder in the
/// exports: "supine", "prone", "right-decubitus", "left-decubitus".
pub fn position_of(study: &Study) -> &'static str {
    match study.segmentation.orientation.position {
        PatientPosition::Hfs | PatientPosition::Ffs => "supine",
        PatientPosition::Hfp | PatientPosition::Ffp => "prone",
        PatientPosition::Hfdr | PatientPosition::Ffdr => "right-decubitus",
        PatientPosition::Hfdl | PatientPosition::Ffdl => "left-decubitus",
    }
}

/// What the user chose for a volume already in memory.
pub struct Choices<'a> {
    pub points: &'a PointArgs,
    /// The volume is a lumen mask.
    pub mask: bool,
    pub nav_min_wall_mm: Option<f64>,
}

/// Preprocesses `ct` (named `name` in errors), whose loader found `meta`, with the user's
/// `choices`; the loader's warnings head the study's. `progress` hears each stage, from
/// step 1 of [`OPEN_STEPS`].
pub fn prepare_volume(
    ct: Volume<i16>,
    meta: io::Meta,
    choices: &Choices,
    name: &str,
    mut progress: impl FnMut(Opening),
) -> Result<Study> {
    let mut opts = PrepOptions::default();
    choices.points.apply(ct.geometry(), &meta, &mut opts);
    opts.segment.mask = choices.mask.then_some(true);
    opts.nav_min_wall_mm = choices.nav_min_wall_mm;
    // Stages come round again (the centerline is traced anew after holes are plugged): the
    // step stays at the furthest reached, so that a bar never runs backwards.
    let mut reached = 0;
    let mut study = prepare(ct, &opts, |stage| {
        let i = Stage::ALL.iter().position(|s| *s == stage).unwrap_or(0);
        reached = reached.max(1 + i);
        progress(Opening {
            step: reached,
            what: stage.name(),
        })
    })
    .with_context(|| name.to_string())?;
    if study.centerline.points_mm.len() < 2 {
        bail!("{name}: the centerline is empty");
    }
    study.segmentation.warnings.splice(0..0, meta.warnings);
    Ok(study)
}
