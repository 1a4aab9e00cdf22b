//! voyage's files: loading and saving volumes and images (the exports other tools open are
//! `voyage-export`'s, over this crate). It depends on `voyage-core` alone.
//!
//! [`load`] takes a path and returns a HU volume with geometry in the DICOM patient frame
//! (LPS), whatever the format: a DICOM series folder or file (also multi-frame), NIfTI-1
//! (.nii, .nii.gz; RAS converted to LPS), MetaImage (.mha, .mhd + raw) or NRRD.

mod alloc_guard;
mod atomic;
pub mod dicom;
pub mod dicom_write;
pub mod metaimage;
pub mod nifti;
pub mod nrrd;
mod panic;
mod png;
mod raw;

pub use alloc_guard::GuardedAllocator;
pub use atomic::write_atomic;
pub use panic::install_panic_hook;
pub use png::{encode_png, write_png};

use std::path::{Path, PathBuf};

use serde::Serialize;

use voyage_core::{Error, Result, Volume};

/// Choices the user can make when loading.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// DICOM: the SeriesInstanceUID to load when a folder holds several series.
    pub series_uid: Option<String>,
}

/// The file formats voyage reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    Dicom,
    Nifti,
    MetaImage,
    Nrrd,
}

/// What a loader learned besides the voxels. Never holds patient name or ID.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Meta {
    pub format: Option<Format>,
    /// e.g. "CT"; None when the format does not say.
    pub modality: Option<String>,
    pub series_uid: Option<String>,
    pub series_description: Option<String>,
    /// Transfer syntax name(s) seen (DICOM only).
    pub transfer_syntaxes: Vec<String>,
    /// Number of files read (DICOM: slices; others: 1 or 2).
    pub files: usize,
    /// Other series found beside the chosen one: (uid, description, slice count).
    pub other_series: Vec<SeriesSummary>,
    /// Things the loader did that the user should know (series chosen, tilt corrected...).
    pub notes: Vec<String>,
    /// Doubtful choices the user must see wherever the study is opened (prep, the window):
    /// a series taken among several without being asked for.
    pub warnings: Vec<String>,
    /// DICOM SeriesNumber (0020,0011), when the file says.
    pub series_number: Option<i64>,
    /// The exam's date as YYYY-MM-DD: DICOM StudyDate (0008,0020), else SeriesDate, else
    /// AcquisitionDate, when one is a valid date.
    pub exam_date: Option<String>,
    /// DICOM PatientPosition (0018,5100), when the file says and the code is known.
    #[serde(skip)]
    pub position: Option<voyage_core::PatientPosition>,
}

#[derive(Clone, Debug, Serialize)]
pub struct SeriesSummary {
    pub uid: String,
    pub description: Option<String>,
    pub modality: Option<String>,
    pub slices: usize,
}

/// A loaded volume of Hounsfield units (or labels, for masks) and what came with it.
#[derive(Clone, Debug)]
pub struct Loaded {
    pub volume: Volume<i16>,
    pub meta: Meta,
}

/// Loads any supported volume from a path (file or DICOM folder).
pub fn load(path: &Path, opts: &LoadOptions) -> Result<Loaded> {
    let md = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    let loaded = if md.is_dir() {
        dicom::load_dir(path, opts)?
    } else {
        match detect_format(path)? {
            Format::Nifti => nifti::load(path)?,
            Format::MetaImage => metaimage::load(path)?,
            Format::Nrrd => nrrd::load(path)?,
            Format::Dicom => dicom::load_file(path, opts)?,
        }
    };
    check_spacing(path, loaded.volume.spacing())?;
    check_values(path, loaded.volume.data())?;
    Ok(loaded)
}

/// The positions an exam at `path` was scanned in, each with its series (see
/// [`dicom::positions_in`]); empty for a file, or a folder whose series do not say how the
/// patient lay.
pub fn positions_in(path: &Path) -> Result<Vec<(voyage_core::PatientPosition, String)>> {
    let md = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if md.is_dir() {
        dicom::positions_in(path)
    } else {
        Ok(Vec::new())
    }
}

/// Most of a volume at the limits of 16-bit values after its rescale is no CT: a slope or
/// intercept out of all proportion (`scl_slope` 1e30 made every voxel 32767, and all of it
/// "lumen"). Padding outside a scan's round field of view is about a fifth of a slice.
const MOST_SATURATED: f64 = 0.5;

fn check_values(path: &Path, data: &[i16]) -> Result<()> {
    // In blocks with a narrow sum, which compiles to vector code: this is one more pass over
    // every voxel loaded.
    let saturated: usize = data
        .chunks(1 << 16)
        .map(|block| {
            block
                .iter()
                .map(|&v| u32::from(v == i16::MAX || v == i16::MIN))
                .sum::<u32>() as usize
        })
        .sum();
    let share = saturated as f64 / data.len().max(1) as f64;
    if share <= MOST_SATURATED {
        return Ok(());
    }
    Err(Error::format(
        path,
        format!(
            "{:.0} % of the voxels lie at the limits of 16-bit values (±32767) after the rescale: these are not CT numbers (check the rescale slope and intercept, scl_slope / scl_inter)",
            share * 100.0
        ),
    ))
}

/// Voxel sizes a scan of a body can have (mm): a header outside them is wrong, and every
/// length the pipeline measures (and allocates by, as the centerline's resampling does)
/// would be out of all proportion.
pub const SPACING_RANGE_MM: std::ops::RangeInclusive<f64> = 0.01..=50.0;

fn check_spacing(path: &Path, spacing: [f64; 3]) -> Result<()> {
    if spacing.iter().all(|s| SPACING_RANGE_MM.contains(s)) {
        return Ok(());
    }
    Err(Error::format(
        path,
        format!(
            "voxel spacing {:?} mm lies outside {}–{} mm: the header's voxel sizes (pixdim, sform, spacing) are not a scan's",
            spacing,
            SPACING_RANGE_MM.start(),
            SPACING_RANGE_MM.end()
        ),
    ))
}

/// Decides the format of a file from its name, then from its first bytes.
pub fn detect_format(path: &Path) -> Result<Format> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    if name.ends_with(".nii") || name.ends_with(".nii.gz") {
        return Ok(Format::Nifti);
    }
    if name.ends_with(".mha") || name.ends_with(".mhd") {
        return Ok(Format::MetaImage);
    }
    if name.ends_with(".nrrd") || name.ends_with(".nhdr") {
        return Ok(Format::Nrrd);
    }
    let mut head = [0u8; 352];
    let n = read_prefix(path, &mut head)?;
    let head = &head[..n];
    if n >= 132 && &head[128..132] == b"DICM" {
        return Ok(Format::Dicom);
    }
    if head.starts_with(b"NRRD") {
        return Ok(Format::Nrrd);
    }
    if n >= 348 && (&head[344..348] == b"n+1\0" || &head[344..348] == b"ni1\0") {
        return Ok(Format::Nifti);
    }
    if name.ends_with(".dcm")
        || name.ends_with(".dicom")
        || !name.contains('.')
        || name.starts_with("ct.")
    {
        // DICOM files without the preamble (old ACR-NEMA style) and extension-less names.
        return Ok(Format::Dicom);
    }
    Err(Error::format(
        path,
        "unknown file format (expected DICOM, NIfTI, MetaImage or NRRD)",
    ))
}

fn read_prefix(path: &Path, buf: &mut [u8]) -> Result<usize> {
    use std::io::Read;
    let mut f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut n = 0;
    while n < buf.len() {
        match f.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(Error::io(path, e)),
        }
    }
    Ok(n)
}

/// Attaches a path to an error that did not have one.
pub(crate) fn at(path: &Path) -> impl Fn(Error) -> Error + '_ {
    move |e| match e {
        Error::Invalid(msg) => Error::format(path, msg),
        other => other,
    }
}

/// Returns the path with its extension(s) replaced, e.g. for the .raw of a .mhd.
/// The data file a detached header (`.mhd` `ElementDataFile`, `.nhdr` `data file:`) names
/// under `key`: only a relative path that stays inside the header's folder (no `..`, no
/// absolute path, no link out of it), and only a regular file (a FIFO or a device would
/// hang the reader or never end), as ITK's readers are commonly configured to.
pub(crate) fn detached_data(header: &Path, name: &str, key: &str) -> Result<PathBuf> {
    use std::path::Component;
    let refuse = |why: &str| Err(Error::format(header, format!("{key} {name}: {why}")));
    let relative = Path::new(name);
    if relative
        .components()
        .any(|c| !matches!(c, Component::Normal(_) | Component::CurDir))
    {
        return refuse("only a file in the header's folder (or below it) is read");
    }
    let data = sibling(header, name);
    let folder = header.parent().filter(|p| !p.as_os_str().is_empty());
    let folder = folder.unwrap_or(Path::new("."));
    let (Ok(real), Ok(home)) = (data.canonicalize(), folder.canonicalize()) else {
        return refuse("no such file beside the header");
    };
    if !real.starts_with(&home) {
        return refuse("it leads out of the header's folder");
    }
    match std::fs::metadata(&real) {
        Ok(m) if m.is_file() => Ok(data),
        Ok(_) => refuse("not a regular file"),
        Err(e) => Err(Error::io(&data, e)),
    }
}

/// Reads a small text file the user names (findings): only a regular file, of at most
/// `max_bytes`; `/dev/zero` or a FIFO would never end.
pub fn read_small_text(path: &Path, max_bytes: u64) -> Result<String> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        return Err(Error::format(path, "not a regular file"));
    }
    if meta.len() > max_bytes {
        return Err(Error::format(
            path,
            format!(
                "{} bytes: more than the {max_bytes} a findings file can hold",
                meta.len()
            ),
        ));
    }
    std::fs::read_to_string(path).map_err(|e| Error::io(path, e))
}

pub(crate) fn sibling(path: &Path, file_name: &str) -> PathBuf {
    path.parent()
        .map(|p| p.join(file_name))
        .unwrap_or_else(|| PathBuf::from(file_name))
}
