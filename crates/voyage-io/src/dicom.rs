//! DICOM loading: a series folder ([`load_dir`]) or one file ([`load_file`], single slice or
//! multi-frame) into a [`Volume<i16>`] of Hounsfield units in the patient frame (LPS).
//!
//! How a folder is read:
//! 1. *Header pass* (parallel): every file's header is parsed up to the pixel data. Files
//!    without the `DICM` marker are skipped (README, thumbnails); DICOM files without an image
//!    (DICOMDIR, structured reports) are skipped with a note. A file that looks like DICOM but
//!    cannot be parsed is an error: it might be a slice of the series, and silently leaving it
//!    out would shift anatomy.
//! 2. *Series choice*: slices are grouped by SeriesInstanceUID; the user's choice wins,
//!    otherwise the CT series with the most slices.
//! 3. *Stack geometry*: slices are sorted by ImagePositionPatient projected on the slice normal
//!    (row cosine × column cosine) — never by file name or InstanceNumber, which scanners and
//!    anonymisers reorder. The gaps must be uniform: a missing slice, uneven gaps or two slices
//!    at one position are errors that name the files on either side.
//! 4. *Pixel pass* (parallel, one slice per task): uncompressed little endian pixel bytes are
//!    taken straight from the file (the fast path a 400-slice series depends on); other syntaxes
//!    go through dicom-rs and its codecs. Values become HU with each slice's own
//!    RescaleSlope/Intercept, saturating to `i16`.
//!
//! Decisions, so that nothing is silently misplaced:
//! - **Gantry tilt is corrected**: when the slice positions step off the slice normal (a tilted
//!   gantry writes tilted orientation cosines but moves the table straight), each slice is
//!   shifted within its own plane by linear interpolation so that the stack becomes an
//!   orthogonal grid along the slice normal. The grid is widened so no voxel is lost; voxels
//!   that no slice covers are set to [`OUTSIDE_HU`]. A note in `Meta::notes` says so.
//! - **Missing PixelSpacing is an error**: it is a required attribute of CT images, and
//!   guessing 1 mm would make every distance and polyp size wrong by an unknown factor.
//! - **Lossy syntaxes are decoded** (JPEG baseline/extended, JPEG-LS near-lossless, JPEG 2000
//!   lossy): their rescale slope maps the stored bits back to HU, so the result is the CT up
//!   to the compression error; a note says the data is lossy.
//!   12-bit lossy JPEG (Process 2 & 4) and the retired JPEG processes (6 & 8, 10 & 12) have no
//!   decoder here and are refused with an error naming the transfer syntax, never decoded into
//!   wrong values.
//! - Only grayscale images (one sample, MONOCHROME1/2, 8 or 16 bits) are read; colour and
//!   palette images are refused, since their values are not HU.
//! - A left-handed stack cannot be told apart in DICOM: the volume is always returned with
//!   k = row cosine × column cosine, slices ascending along it.
//! - Subfolders are not searched.
//!
//! Robustness: the file meta group is parsed leniently here and rewritten for dicom-rs (real
//! files break its rules), every element length is checked against the file size before
//! dicom-rs allocates for it, image sizes go through [`check_dims`], and any panic inside the
//! DICOM libraries is caught and reported as an error naming the file.
//!
//! Patient name and ID are never read.

use std::{
    collections::BTreeMap,
    panic::{AssertUnwindSafe, catch_unwind},
    path::{Path, PathBuf},
};

use dicom_core::{
    Tag,
    value::{PrimitiveValue, Value},
};
use dicom_dictionary_std::tags;
use dicom_encoding::transfer_syntax::{Endianness, TransferSyntaxIndex};
use dicom_object::{DefaultDicomObject, InMemDicomObject, OpenFileOptions};
use dicom_transfer_syntax_registry::TransferSyntaxRegistry;
use glam::DVec3;
use rayon::prelude::*;

use super::{Format, LoadOptions, Loaded, Meta, SeriesSummary};
use voyage_core::{Error, Geometry, Result, Volume, check_dims};

/// Value given to voxels of a tilt-corrected grid that no acquired slice covers (air).
pub const OUTSIDE_HU: i16 = -1024;

/// Relative and absolute tolerance on slice gaps: a gap may differ from the typical one by at
/// most `max(GAP_TOL_MM, GAP_TOL_REL × gap)`. Real series round their positions to 0.1 mm
/// (a 0.625 mm series then steps 0.6 and 0.7 mm); dcm2niix and ITK accept as much, and the
/// slices are placed at the mean gap, nothing resampled.
const GAP_TOL_MM: f64 = 0.1 + 1e-6;
const GAP_TOL_REL: f64 = 0.1;
/// Tolerance on direction cosines and pixel spacing agreeing between slices.
const COSINE_TOL: f64 = 1e-4;

/// The SOP class of a DICOMDIR (an index of a disc, not an image).
const MEDIA_STORAGE_DIRECTORY: &str = "1.2.840.10008.1.3.10";

// ---------------------------------------------------------------------------------------------
// Public entry points
// ---------------------------------------------------------------------------------------------

/// Loads the DICOM series in a folder (not its subfolders). See the module doc for the rules.
pub fn load_dir(path: &Path, opts: &LoadOptions) -> Result<Loaded> {
    let files = list_files(path)?;
    let headers: Vec<Result<Probe>> = files.par_iter().map(|f| probe_file(f)).collect();
    let mut images = Vec::new();
    let mut skipped_non_dicom = Vec::new();
    let mut skipped_non_image = Vec::new();
    let mut unusable: Vec<(String, Error)> = Vec::new();
    for probe in headers {
        match probe? {
            Probe::NotDicom(p) => skipped_non_dicom.push(p),
            Probe::NotImage(p, why) => skipped_non_image.push((p, why)),
            Probe::Image(h) => images.push(*h),
            Probe::Unusable { series_uid, error } => unusable.push((series_uid, error)),
        }
    }
    // Only the series loaded must be loadable: the one asked for, else the one chosen.
    let fails = |uid: &str| unusable.iter().position(|(u, _)| u == uid);
    if let Some(i) = opts.series_uid.as_deref().and_then(fails) {
        return Err(unusable.swap_remove(i).1);
    }
    if images.is_empty() {
        if let Some((_, error)) = unusable.into_iter().next() {
            return Err(error);
        }
        return Err(no_images_error(
            path,
            files.len(),
            &skipped_non_dicom,
            &skipped_non_image,
        ));
    }
    let mut notes = skipped_notes(&skipped_non_dicom, &skipped_non_image);
    let gzipped = gzipped_files(&skipped_non_dicom);
    notes.extend(gzipped.clone().map(|g| format!("not read: {g}")));
    let (chosen, others, choice_note) = choose_series(path, images, opts)?;
    if let Some(i) = chosen.first().and_then(|h| fails(&h.series_uid)) {
        return Err(unusable.swap_remove(i).1);
    }
    if let Some((uid, error)) = unusable.first() {
        notes.push(format!(
            "skipped {} image(s) of other series that cannot be loaded, e.g. of series {uid}: {error}",
            unusable.len()
        ));
    }
    let warning = choice_note
        .as_ref()
        .filter(|_| opts.series_uid.is_none())
        .map(|n| format!("{n}; --series UID loads another (`voyage info` lists them)"));
    notes.extend(choice_note);
    let mut loaded = load_series(chosen).map_err(|e| match &gzipped {
        // A slice left compressed is what a gap or a missing slice may come from.
        Some(g) => Error::format(path, format!("{e}; the folder also holds {g}")),
        None => e,
    })?;
    loaded.meta.other_series = others;
    loaded.meta.warnings.extend(warning);
    notes.append(&mut loaded.meta.notes);
    loaded.meta.notes = notes;
    Ok(loaded)
}

/// Loads one DICOM file: a multi-frame image becomes a volume of its frames, a single slice a
/// volume one voxel deep (k spacing from SpacingBetweenSlices, else SliceThickness, else 1 mm).
/// When `opts.series_uid` is given, the file must belong to that series.
pub fn load_file(path: &Path, opts: &LoadOptions) -> Result<Loaded> {
    match probe_file(path)? {
        Probe::NotDicom(_) => Err(Error::format(
            path,
            "not a DICOM file (no 'DICM' marker at byte 128; files without the DICOM Part 10 header are not supported)",
        )),
        Probe::NotImage(_, why) => Err(Error::format(path, format!("no image to load: {why}"))),
        Probe::Unusable { error, .. } => Err(error),
        Probe::Image(h) => match &opts.series_uid {
            Some(want) if *want != h.series_uid => Err(Error::format(
                path,
                format!(
                    "this file belongs to series {}, not to the requested {want}",
                    h.series_uid
                ),
            )),
            _ => load_series(vec![*h]),
        },
    }
}

// ---------------------------------------------------------------------------------------------
// Header pass
// ---------------------------------------------------------------------------------------------

/// What the header pass learned about one file.
enum Probe {
    NotDicom(PathBuf),
    /// A DICOM file without an image, and why (shown when a folder holds no image at all).
    NotImage(PathBuf, String),
    Image(Box<Header>),
    /// An image of the series `series_uid` that cannot be loaded, and why.
    Unusable {
        series_uid: String,
        error: Error,
    },
}

/// The header of one image file, with the pixel data not read.
#[derive(Clone, Debug)]
struct Header {
    path: PathBuf,
    series_uid: String,
    series_description: Option<String>,
    modality: Option<String>,
    ts_uid: String,
    rows: usize,
    cols: usize,
    frames: usize,
    pixel: PixelFormat,
    /// One entry per frame.
    planes: Vec<Plane>,
    /// SpacingBetweenSlices, else SliceThickness (for single slices and multi-frame files
    /// without per-frame positions).
    slice_step: Option<f64>,
    gantry_tilt_deg: Option<f64>,
    /// LossyImageCompression is "01": the pixels went through lossy compression at some point.
    lossy: bool,
    /// PatientPosition (0018,5100) as written ("HFS", "FFP", ...).
    position: Option<String>,
    series_number: Option<i64>,
    /// YYYY-MM-DD ([`exam_date`]).
    exam_date: Option<String>,
}

/// How stored pixel values are laid out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct PixelFormat {
    bits_allocated: u16,
    bits_stored: u16,
    high_bit: u16,
    signed: bool,
}

impl PixelFormat {
    fn bytes_per_sample(&self) -> usize {
        usize::from(self.bits_allocated / 8)
    }
}

/// Stored value → HU: `hu = stored × slope + intercept`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Rescale {
    slope: f64,
    intercept: f64,
}

/// Where one frame lies in the patient, as its header says.
#[derive(Clone, Debug)]
struct Plane {
    position: Option<DVec3>,
    /// Row cosine (direction of increasing column index, i) and column cosine (increasing row
    /// index, j).
    orientation: Option<[DVec3; 2]>,
    /// [along i (between columns), along j (between rows)] in mm. DICOM PixelSpacing lists them
    /// the other way round: row spacing first.
    spacing: Option<[f64; 2]>,
    rescale: Rescale,
}

fn list_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))?;
    let mut files = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| Error::io(dir, e))?;
        let path = entry.path();
        if path.is_file() {
            files.push(path);
        }
    }
    files.sort();
    Ok(files)
}

/// Reads one file's header, turning any panic inside the DICOM parser into an error.
fn probe_file(path: &Path) -> Result<Probe> {
    if !has_dicm_marker(path)? {
        return Ok(Probe::NotDicom(path.to_path_buf()));
    }
    let obj = guarded(path, "reading the header", || {
        open_dicom(path, Some(tags::PIXEL_DATA))
            .map_err(|e| e.into_error(path, "not a readable DICOM file"))
    })?;
    guarded(path, "reading the header", || {
        // An image voyage cannot load (a colour dose screen, a 32-bit map) matters only when
        // its series is the one loaded: its series is kept with the error.
        parse_header(path, &obj).or_else(|m| match text(&obj, tags::SERIES_INSTANCE_UID) {
            Some(series_uid) => Ok(Probe::Unusable {
                series_uid,
                error: Error::format(path, m),
            }),
            None => Err(Error::format(path, m)),
        })
    })
}

/// Whether the file carries the DICOM Part 10 marker ("DICM" after the 128-byte preamble, or at
/// the start of a file whose preamble was stripped).
fn has_dicm_marker(path: &Path) -> Result<bool> {
    let mut head = [0u8; 132];
    let n = super::read_prefix(path, &mut head)?;
    Ok((n >= 132 && &head[128..132] == b"DICM") || (n >= 4 && &head[0..4] == b"DICM"))
}

/// Runs `f`, converting a panic (a bug or an unchecked case in a decoder) into an error that
/// names the file, so that no input can crash the program.
fn guarded<T>(path: &Path, what: &str, f: impl FnOnce() -> Result<T>) -> Result<T> {
    let result = crate::panic::quietly(|| catch_unwind(AssertUnwindSafe(f)));
    match result {
        Ok(r) => r,
        Err(panic) => {
            let msg = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown cause".into());
            Err(Error::format(
                path,
                format!("malformed DICOM data: the reader failed while {what} ({msg})"),
            ))
        }
    }
}

/// A library error with its causes, on one line.
fn error_chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut src = e.source();
    while let Some(cause) = src {
        let c = cause.to_string();
        if !s.contains(&c) {
            s.push_str(": ");
            s.push_str(&c);
        }
        src = cause.source();
    }
    s
}

fn parse_header(path: &Path, obj: &DefaultDicomObject) -> std::result::Result<Probe, String> {
    let sop_class = text(obj, tags::SOP_CLASS_UID);
    let modality = text(obj, tags::MODALITY);
    if sop_class.as_deref() == Some(MEDIA_STORAGE_DIRECTORY) {
        return Ok(Probe::NotImage(
            path.to_path_buf(),
            "a DICOMDIR (directory index)".into(),
        ));
    }
    let (Some(rows), Some(cols)) = (
        uint(obj, tags::ROWS, "Rows")?,
        uint(obj, tags::COLUMNS, "Columns")?,
    ) else {
        let what = match (&modality, &sop_class) {
            (Some(m), _) => format!("modality {m}"),
            (None, Some(c)) => format!("SOP class {c}"),
            _ => "no modality".into(),
        };
        return Ok(Probe::NotImage(
            path.to_path_buf(),
            format!("no image in this file (no Rows/Columns; {what})"),
        ));
    };
    let frames = uint(obj, tags::NUMBER_OF_FRAMES, "NumberOfFrames")?.unwrap_or(1);
    check_dims([cols, rows, frames]).map_err(|e| format!("image size: {e}"))?;
    let pixel = parse_pixel_format(obj)?;
    let planes = parse_planes(obj, frames as usize)?;
    let slice_step = match float(obj, tags::SPACING_BETWEEN_SLICES, "SpacingBetweenSlices")? {
        Some(s) if s.abs() > 0.0 => Some(s.abs()),
        _ => float(obj, tags::SLICE_THICKNESS, "SliceThickness")?.filter(|t| *t > 0.0),
    };
    Ok(Probe::Image(Box::new(Header {
        path: path.to_path_buf(),
        series_uid: text(obj, tags::SERIES_INSTANCE_UID).unwrap_or_default(),
        series_description: text(obj, tags::SERIES_DESCRIPTION),
        series_number: text(obj, tags::SERIES_NUMBER).and_then(|t| t.parse().ok()),
        exam_date: exam_date(obj),
        modality,
        ts_uid: obj
            .meta()
            .transfer_syntax()
            .trim_end_matches(['\0', ' '])
            .to_string(),
        rows: rows as usize,
        cols: cols as usize,
        frames: frames as usize,
        pixel,
        planes,
        slice_step,
        gantry_tilt_deg: float(obj, tags::GANTRY_DETECTOR_TILT, "GantryDetectorTilt")?,
        lossy: text(obj, tags::LOSSY_IMAGE_COMPRESSION).as_deref() == Some("01"),
        position: text(obj, tags::PATIENT_POSITION),
    })))
}

/// Checks the pixel module: one grayscale sample of 8 or 16 bits.
fn parse_pixel_format(obj: &InMemDicomObject) -> std::result::Result<PixelFormat, String> {
    let samples = uint(obj, tags::SAMPLES_PER_PIXEL, "SamplesPerPixel")?.unwrap_or(1);
    let photometric =
        text(obj, tags::PHOTOMETRIC_INTERPRETATION).unwrap_or_else(|| "MONOCHROME2".into());
    if samples != 1 || !photometric.starts_with("MONOCHROME") {
        return Err(format!(
            "not a grayscale image (SamplesPerPixel {samples}, PhotometricInterpretation {photometric}): its values are not CT numbers"
        ));
    }
    let bits_allocated = uint(obj, tags::BITS_ALLOCATED, "BitsAllocated")?
        .ok_or("BitsAllocated (0028,0100) is missing")?;
    if bits_allocated != 8 && bits_allocated != 16 {
        return Err(format!(
            "BitsAllocated {bits_allocated} is not supported (CT images use 8 or 16)"
        ));
    }
    let bits_stored = uint(obj, tags::BITS_STORED, "BitsStored")?.unwrap_or(bits_allocated);
    let high_bit = uint(obj, tags::HIGH_BIT, "HighBit")?.unwrap_or(bits_stored.saturating_sub(1));
    if bits_stored == 0
        || bits_stored > bits_allocated
        || high_bit >= bits_allocated
        || high_bit + 1 < bits_stored
    {
        return Err(format!(
            "inconsistent bit layout: BitsAllocated {bits_allocated}, BitsStored {bits_stored}, HighBit {high_bit}"
        ));
    }
    let representation = uint(obj, tags::PIXEL_REPRESENTATION, "PixelRepresentation")?.unwrap_or(0);
    Ok(PixelFormat {
        bits_allocated: bits_allocated as u16,
        bits_stored: bits_stored as u16,
        high_bit: high_bit as u16,
        signed: representation == 1,
    })
}

/// The plane of each frame: per-frame functional groups first (enhanced multi-frame), then the
/// shared functional groups, then the classic top-level attributes.
fn parse_planes(obj: &InMemDicomObject, frames: usize) -> std::result::Result<Vec<Plane>, String> {
    let shared = obj
        .get(tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE)
        .and_then(|e| e.items())
        .and_then(|i| i.first());
    let per_frame = obj
        .get(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE)
        .and_then(|e| e.items());
    if let Some(items) = per_frame
        && items.len() != frames
    {
        return Err(format!(
            "PerFrameFunctionalGroupsSequence has {} items for {frames} frames",
            items.len()
        ));
    }
    (0..frames)
        .map(|f| {
            let groups = [per_frame.and_then(|items| items.get(f)), shared];
            let at =
                |seq: Tag, tag: Tag, name: &str| grouped_floats(Some(obj), &groups, seq, tag, name);
            // A multi-frame file's shared or top-level position is that of its first frame.
            let position = if frames == 1 || f == 0 {
                at(
                    tags::PLANE_POSITION_SEQUENCE,
                    tags::IMAGE_POSITION_PATIENT,
                    "ImagePositionPatient",
                )?
            } else {
                grouped_floats(
                    None,
                    &groups[..1],
                    tags::PLANE_POSITION_SEQUENCE,
                    tags::IMAGE_POSITION_PATIENT,
                    "ImagePositionPatient",
                )?
            };
            let position = position
                .map(|v| vec3(&v, "ImagePositionPatient"))
                .transpose()?;
            let orientation = at(
                tags::PLANE_ORIENTATION_SEQUENCE,
                tags::IMAGE_ORIENTATION_PATIENT,
                "ImageOrientationPatient",
            )?
            .map(|v| orientation(&v))
            .transpose()?;
            let spacing = at(
                tags::PIXEL_MEASURES_SEQUENCE,
                tags::PIXEL_SPACING,
                "PixelSpacing",
            )?
            .map(|v| pixel_spacing(&v))
            .transpose()?;
            let seq = tags::PIXEL_VALUE_TRANSFORMATION_SEQUENCE;
            let slope = at(seq, tags::RESCALE_SLOPE, "RescaleSlope")?
                .and_then(|v| v.first().copied())
                .unwrap_or(1.0);
            let intercept = at(seq, tags::RESCALE_INTERCEPT, "RescaleIntercept")?
                .and_then(|v| v.first().copied())
                .unwrap_or(0.0);
            if slope == 0.0 {
                return Err("RescaleSlope is 0".to_string());
            }
            Ok(Plane {
                position,
                orientation,
                spacing,
                rescale: Rescale { slope, intercept },
            })
        })
        .collect()
}

/// Looks an attribute up inside a functional group sequence of each group set in turn, then at
/// the top level (when given).
fn grouped_floats(
    top: Option<&InMemDicomObject>,
    groups: &[Option<&InMemDicomObject>],
    seq: Tag,
    tag: Tag,
    name: &str,
) -> std::result::Result<Option<Vec<f64>>, String> {
    for group in groups.iter().flatten() {
        let item = group
            .get(seq)
            .and_then(|e| e.items())
            .and_then(|i| i.first());
        if let Some(item) = item
            && let Some(v) = floats(item, tag, name)?
        {
            return Ok(Some(v));
        }
    }
    match top {
        Some(obj) => floats(obj, tag, name),
        None => Ok(None),
    }
}

fn vec3(v: &[f64], name: &str) -> std::result::Result<DVec3, String> {
    match v {
        [x, y, z] => Ok(DVec3::new(*x, *y, *z)),
        _ => Err(format!("{name} has {} values, expected 3", v.len())),
    }
}

/// Checks that ImageOrientationPatient holds two orthogonal unit vectors, and makes them
/// exactly orthonormal (values are written with a few decimals).
fn orientation(v: &[f64]) -> std::result::Result<[DVec3; 2], String> {
    let [rx, ry, rz, cx, cy, cz] = v else {
        return Err(format!(
            "ImageOrientationPatient has {} values, expected 6",
            v.len()
        ));
    };
    let row = DVec3::new(*rx, *ry, *rz);
    let col = DVec3::new(*cx, *cy, *cz);
    let unit = |a: DVec3| (a.length() - 1.0).abs() < 1e-3;
    if !unit(row) || !unit(col) || row.dot(col).abs() > 1e-3 {
        return Err(format!(
            "ImageOrientationPatient {v:?} is not two orthogonal unit vectors"
        ));
    }
    let row = row.normalize();
    let col = (col - row * row.dot(col)).normalize();
    Ok([row, col])
}

fn pixel_spacing(v: &[f64]) -> std::result::Result<[f64; 2], String> {
    match v {
        [between_rows, between_cols] if *between_rows > 0.0 && *between_cols > 0.0 => {
            Ok([*between_cols, *between_rows])
        }
        _ => Err(format!("PixelSpacing {v:?} is not two positive numbers")),
    }
}

fn text(obj: &InMemDicomObject, tag: Tag) -> Option<String> {
    let s = obj.get(tag)?.to_str().ok()?;
    let s = s.trim_matches(|c: char| c.is_whitespace() || c == '\0');
    (!s.is_empty()).then(|| s.to_string())
}

/// The exam's date, YYYY-MM-DD: StudyDate, else SeriesDate, else AcquisitionDate (DA,
/// "YYYYMMDD"; the old "YYYY.MM.DD" too). A value that is not a date is passed over.
fn exam_date(obj: &InMemDicomObject) -> Option<String> {
    [tags::STUDY_DATE, tags::SERIES_DATE, tags::ACQUISITION_DATE]
        .into_iter()
        .find_map(|tag| {
            let digits: String = text(obj, tag)?.chars().filter(|c| *c != '.').collect();
            let (y, m, d) = (
                digits.get(0..4)?.parse::<u32>().ok()?,
                digits.get(4..6)?.parse::<u32>().ok()?,
                digits.get(6..8)?.parse::<u32>().ok()?,
            );
            (digits.len() == 8
                && (1900..=2200).contains(&y)
                && (1..=12).contains(&m)
                && (1..=31).contains(&d))
            .then(|| format!("{y:04}-{m:02}-{d:02}"))
        })
}

/// An unsigned integer attribute: `None` when absent or empty, an error when unreadable.
fn uint(obj: &InMemDicomObject, tag: Tag, name: &str) -> std::result::Result<Option<u64>, String> {
    let Some(elem) = obj.get(tag) else {
        return Ok(None);
    };
    if is_empty(elem) {
        return Ok(None);
    }
    elem.to_int::<u64>().map(Some).map_err(|_| {
        let raw = elem
            .to_str()
            .map(|s| s.trim().to_string())
            .unwrap_or_default();
        format!(
            "{name} ({:04X},{:04X}) is '{raw}', not a whole number",
            tag.group(),
            tag.element()
        )
    })
}

/// An element present with no value (allowed for Type 2 attributes).
fn is_empty(elem: &dicom_object::mem::InMemElement) -> bool {
    match elem.value() {
        Value::Primitive(PrimitiveValue::Empty) => true,
        Value::Primitive(p) => p
            .to_str()
            .trim_matches(|c: char| c.is_whitespace() || c == '\0')
            .is_empty(),
        _ => false,
    }
}

fn float(obj: &InMemDicomObject, tag: Tag, name: &str) -> std::result::Result<Option<f64>, String> {
    Ok(floats(obj, tag, name)?.and_then(|v| v.first().copied()))
}

/// A decimal attribute with any number of values: `None` when absent or empty, an error when
/// unreadable or not finite.
fn floats(
    obj: &InMemDicomObject,
    tag: Tag,
    name: &str,
) -> std::result::Result<Option<Vec<f64>>, String> {
    let Some(elem) = obj.get(tag) else {
        return Ok(None);
    };
    if is_empty(elem) {
        return Ok(None);
    }
    match elem.to_multi_float64() {
        Ok(v) if v.iter().all(|x| x.is_finite()) => Ok(Some(v)),
        _ => {
            let raw = elem
                .to_str()
                .map(|s| s.trim().to_string())
                .unwrap_or_default();
            Err(format!(
                "{name} ({:04X},{:04X}) is '{raw}', not a list of numbers",
                tag.group(),
                tag.element()
            ))
        }
    }
}

fn no_images_error(
    dir: &Path,
    n_files: usize,
    non_dicom: &[PathBuf],
    non_image: &[(PathBuf, String)],
) -> Error {
    let mut msg = format!("no DICOM images in folder ({n_files} files");
    if !non_dicom.is_empty() {
        msg.push_str(&format!(", {} not DICOM", non_dicom.len()));
    }
    msg.push(')');
    for (p, why) in non_image.iter().take(5) {
        msg.push_str(&format!("; {}: {why}", file_name(p)));
    }
    Error::format(dir, msg)
}

/// The files among `non_dicom` that are gzip-compressed (`.dcm.gz`, or a `.gz` among plain
/// slices), named: voyage reads no compressed DICOM file, and says which it left.
fn gzipped_files(non_dicom: &[PathBuf]) -> Option<String> {
    let gz: Vec<String> = non_dicom
        .iter()
        .filter(|p| {
            let mut head = [0u8; 2];
            matches!(super::read_prefix(p, &mut head), Ok(2)) && head == [0x1f, 0x8b]
        })
        .map(|p| file_name(p))
        .collect();
    let shown: Vec<&str> = gz.iter().take(5).map(String::as_str).collect();
    (!gz.is_empty()).then(|| {
        format!(
            "{} gzip-compressed file(s), which voyage does not read ({}{}): gunzip them",
            gz.len(),
            shown.join(", "),
            if gz.len() > shown.len() { ", ..." } else { "" }
        )
    })
}

fn skipped_notes(non_dicom: &[PathBuf], non_image: &[(PathBuf, String)]) -> Vec<String> {
    let mut notes = Vec::new();
    if !non_dicom.is_empty() {
        notes.push(format!(
            "skipped {} non-DICOM file(s), e.g. {}",
            non_dicom.len(),
            file_name(&non_dicom[0])
        ));
    }
    if !non_image.is_empty() {
        let (p, why) = &non_image[0];
        notes.push(format!(
            "skipped {} DICOM file(s) without an image, e.g. {} ({why})",
            non_image.len(),
            file_name(p)
        ));
    }
    notes
}

fn file_name(p: &Path) -> String {
    p.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| p.display().to_string())
}

// ---------------------------------------------------------------------------------------------
// Series choice
// ---------------------------------------------------------------------------------------------

type Choice = (Vec<Header>, Vec<SeriesSummary>, Option<String>);

/// Picks the series to load: the one the user named, else the CT series with the most slices
/// (ties broken by UID, so the choice is deterministic). Returns it, the others, and a note.
fn choose_series(dir: &Path, images: Vec<Header>, opts: &LoadOptions) -> Result<Choice> {
    let mut groups: BTreeMap<String, Vec<Header>> = BTreeMap::new();
    for h in images {
        groups.entry(h.series_uid.clone()).or_default().push(h);
    }
    let summaries: Vec<SeriesSummary> = groups.iter().map(|(uid, hs)| summary(uid, hs)).collect();
    let chosen_uid = match &opts.series_uid {
        Some(want) => {
            if !groups.contains_key(want) {
                let list: Vec<String> = summaries.iter().map(describe_series).collect();
                return Err(Error::format(
                    dir,
                    format!(
                        "series {want} not found; the folder holds: {}",
                        list.join("; ")
                    ),
                ));
            }
            want.clone()
        }
        None => {
            let best = summaries
                .iter()
                .max_by_key(|s| (rank(s), std::cmp::Reverse(s.uid.clone())));
            best.map(|s| s.uid.clone()).unwrap_or_default()
        }
    };
    let others: Vec<SeriesSummary> = summaries
        .iter()
        .filter(|s| s.uid != chosen_uid)
        .cloned()
        .collect();
    let note = (!others.is_empty()).then(|| {
        let chosen = summaries.iter().find(|s| s.uid == chosen_uid);
        let tied: Vec<String> = others
            .iter()
            .filter(|o| chosen.is_some_and(|c| rank(o) == rank(c)))
            .map(describe_series)
            .collect();
        let mut how = match chosen {
            _ if opts.series_uid.is_some() => "as asked".to_string(),
            Some(s) if s.modality.as_deref() == Some("CT") => {
                "the CT series with the most slices".to_string()
            }
            _ => "no CT series; the series with the most slices".to_string(),
        };
        if opts.series_uid.is_none() && !tied.is_empty() {
            how += &format!(", tied with {} and taken by UID order", tied.join(" and "));
        }
        let chosen = chosen.map(describe_series).unwrap_or_default();
        format!(
            "the folder holds {} series; loaded {chosen}: {how}",
            summaries.len()
        )
    });
    let chosen = groups.remove(&chosen_uid).unwrap_or_default();
    Ok((chosen, others, note))
}

/// How a series ranks when none is asked for: CT first, then the most slices (a tie is
/// broken by UID, and named).
fn rank(s: &SeriesSummary) -> (bool, usize) {
    (s.modality.as_deref() == Some("CT"), s.slices)
}

fn summary(uid: &str, headers: &[Header]) -> SeriesSummary {
    SeriesSummary {
        uid: uid.to_string(),
        description: headers.iter().find_map(|h| h.series_description.clone()),
        modality: headers.iter().find_map(|h| h.modality.clone()),
        slices: headers.iter().map(|h| h.frames).sum(),
    }
}

fn describe_series(s: &SeriesSummary) -> String {
    let uid = if s.uid.is_empty() {
        "(no SeriesInstanceUID)"
    } else {
        &s.uid
    };
    // No SeriesDescription: it is free text, and can hold a name (`info --show-descriptions`
    // lists them).
    format!(
        "{uid} ({}, {} slices)",
        s.modality.as_deref().unwrap_or("no modality"),
        s.slices
    )
}

// ---------------------------------------------------------------------------------------------
// Stack geometry
// ---------------------------------------------------------------------------------------------

/// One slice of the stack: a frame of a file.
#[derive(Clone, Debug)]
struct SliceRef {
    file: usize,
    frame: usize,
    plane: Plane,
}

/// The slices in order along k, the grid they lie on, and what was noticed.
struct Stack {
    slices: Vec<SliceRef>,
    geometry: Geometry,
    /// In-plane shift (mm along i and j) of slice k+1 relative to slice k when the positions
    /// step off the normal (gantry tilt); `None` for an orthogonal stack.
    shear: Option<[f64; 2]>,
    notes: Vec<String>,
    /// What the user must see: slices left out.
    warnings: Vec<String>,
}

fn slice_label(headers: &[Header], s: &SliceRef) -> String {
    let h = &headers[s.file];
    if h.frames > 1 {
        format!("{} frame {}", file_name(&h.path), s.frame + 1)
    } else {
        file_name(&h.path)
    }
}

/// Checks that all slices agree on size, pixel layout, orientation and spacing, sorts them
/// along the normal and checks that the gaps are uniform.
fn build_stack(headers: &[Header]) -> Result<Stack> {
    let first = &headers[0];
    for h in &headers[1..] {
        if (h.rows, h.cols) != (first.rows, first.cols) {
            return Err(Error::format(
                &h.path,
                format!(
                    "image size {}×{} differs from {} ({}×{}) in the same series",
                    h.cols,
                    h.rows,
                    file_name(&first.path),
                    first.cols,
                    first.rows
                ),
            ));
        }
    }
    let slices: Vec<SliceRef> = headers
        .iter()
        .enumerate()
        .flat_map(|(file, h)| {
            h.planes.iter().enumerate().map(move |(frame, p)| SliceRef {
                file,
                frame,
                plane: p.clone(),
            })
        })
        .collect();
    let path_of = |s: &SliceRef| headers[s.file].path.clone();
    let mut notes = Vec::new();

    let spacing = common_spacing(headers, &slices)?;
    let [row, col] = common_orientation(headers, &slices, &mut notes)?;
    let normal = row.cross(col);

    let unplaced_frames =
        headers.len() == 1 && slices[1..].iter().all(|s| s.plane.position.is_none());
    if slices.len() == 1 || unplaced_frames {
        return single_file_stack(&headers[0], slices, spacing, [row, col, normal], notes);
    }
    if let Some(s) = slices.iter().find(|s| s.plane.position.is_none()) {
        return Err(Error::format(
            path_of(s),
            format!(
                "{}: ImagePositionPatient is missing",
                slice_label(headers, s)
            ),
        ));
    }
    let mut slices = slices;
    let pos = |s: &SliceRef| s.plane.position.unwrap_or_default();
    slices.sort_by(|a, b| {
        pos(a)
            .dot(normal)
            .total_cmp(&pos(b).dot(normal))
            .then(a.file.cmp(&b.file))
            .then(a.frame.cmp(&b.frame))
    });
    let mut warnings = Vec::new();
    let slices = drop_copies(headers, slices, &mut warnings);

    let steps: Vec<DVec3> = slices.windows(2).map(|w| pos(&w[1]) - pos(&w[0])).collect();
    let gaps: Vec<f64> = steps.iter().map(|s| s.dot(normal)).collect();
    let tilt = tilt_note(headers, &steps, normal);
    check_gaps(headers, &slices, &gaps, tilt.as_deref())?;

    let n = slices.len();
    let total = pos(&slices[n - 1]) - pos(&slices[0]);
    let dz = total.dot(normal) / (n - 1) as f64;
    let drift = (total - normal * total.dot(normal)) / (n - 1) as f64;
    check_straight_line(headers, &slices, &steps, drift, normal, dz)?;
    let shear_mm = [drift.dot(row), drift.dot(col)];
    // Drift over the whole stack, in pixels. Below a quarter pixel it is rounding in the
    // positions (or a tilt too small to matter), and resampling would only blur.
    let drift_px =
        (shear_mm[0].abs() / spacing[0]).max(shear_mm[1].abs() / spacing[1]) * (n - 1) as f64;
    let negligible = drift_px <= 0.25;
    if negligible && drift_px > 0.01 {
        notes
            .push(format!("slice positions drift {drift_px:.2} pixel within the slice plane over the series: ignored"));
    }
    if negligible && let Some(t) = first.gantry_tilt_deg.filter(|t| t.abs() > 0.01) {
        notes.push(format!(
            "GantryDetectorTilt is {t}°, but the slice positions follow the slice normal: no correction needed"
        ));
    }

    let mut geometry = Geometry::new(
        [first.cols, first.rows, n],
        [spacing[0], spacing[1], dz],
        pos(&slices[0]).to_array(),
    )
    .map_err(super::at(&first.path))?;
    geometry.set_direction_mat(glam::DMat3::from_cols(row, col, normal));
    Ok(Stack {
        slices,
        geometry,
        shear: (!negligible).then_some(shear_mm),
        notes,
        warnings,
    })
}

/// `slices` (sorted along the normal) without the byte-identical copies of a file at the same
/// position (a slice exported twice): each left out is warned about. Two different slices at
/// one position stay, for the gap check to refuse.
fn drop_copies(
    headers: &[Header],
    slices: Vec<SliceRef>,
    warnings: &mut Vec<String>,
) -> Vec<SliceRef> {
    let pos = |s: &SliceRef| s.plane.position.unwrap_or_default();
    let same_bytes = |a: &SliceRef, b: &SliceRef| {
        let (pa, pb) = (&headers[a.file].path, &headers[b.file].path);
        matches!((std::fs::read(pa), std::fs::read(pb)), (Ok(x), Ok(y)) if x == y)
    };
    let mut kept: Vec<SliceRef> = Vec::with_capacity(slices.len());
    for s in slices {
        let copy = kept
            .iter()
            .rev()
            .take_while(|k| pos(k).distance(pos(&s)) < 1e-3)
            .find(|k| k.file != s.file && k.frame == s.frame && same_bytes(k, &s));
        if let Some(k) = copy {
            warnings.push(format!(
                "{} is a byte-identical copy of {}: left out",
                slice_label(headers, &s),
                slice_label(headers, k)
            ));
            continue;
        }
        kept.push(s);
    }
    kept
}

/// A single slice, or a multi-frame file whose frames carry no positions: frames are stacked
/// along the normal at SpacingBetweenSlices (else SliceThickness, else 1 mm).
fn single_file_stack(
    header: &Header,
    slices: Vec<SliceRef>,
    spacing: [f64; 2],
    axes: [DVec3; 3],
    mut notes: Vec<String>,
) -> Result<Stack> {
    let dz = match header.slice_step {
        Some(s) => s,
        None => {
            notes.push(
                "no SpacingBetweenSlices or SliceThickness: slice spacing assumed to be 1 mm"
                    .into(),
            );
            1.0
        }
    };
    let origin = match slices[0].plane.position {
        Some(p) => p,
        None => {
            notes.push("no ImagePositionPatient: origin set to (0, 0, 0)".into());
            DVec3::ZERO
        }
    };
    if slices.len() > 1 {
        notes.push(format!(
            "frames carry no positions: stacked along the slice normal {dz} mm apart"
        ));
    }
    let mut geometry = Geometry::new(
        [header.cols, header.rows, slices.len()],
        [spacing[0], spacing[1], dz],
        origin.to_array(),
    )
    .map_err(super::at(&header.path))?;
    geometry.set_direction_mat(glam::DMat3::from_cols(axes[0], axes[1], axes[2]));
    Ok(Stack {
        slices,
        geometry,
        shear: None,
        notes,
        warnings: Vec::new(),
    })
}

/// All slices must share PixelSpacing (the one CT attribute voyage will not guess).
fn common_spacing(headers: &[Header], slices: &[SliceRef]) -> Result<[f64; 2]> {
    let first = &slices[0];
    let Some(spacing) = first.plane.spacing else {
        return Err(Error::format(
            &headers[first.file].path,
            "PixelSpacing (0028,0030) is missing: the voxel size is unknown, so distances and polyp sizes could not be measured",
        ));
    };
    for s in slices {
        let ok = s
            .plane
            .spacing
            .is_some_and(|p| (0..2).all(|a| (p[a] - spacing[a]).abs() <= COSINE_TOL * spacing[a]));
        if !ok {
            return Err(Error::format(
                &headers[s.file].path,
                format!(
                    "{}: PixelSpacing {:?} differs from {} ({:?}) in the same series",
                    slice_label(headers, s),
                    s.plane.spacing.map(|p| [p[1], p[0]]),
                    slice_label(headers, first),
                    [spacing[1], spacing[0]]
                ),
            ));
        }
    }
    Ok(spacing)
}

/// All slices must share one orientation; a lone slice without one is taken as axial.
fn common_orientation(
    headers: &[Header],
    slices: &[SliceRef],
    notes: &mut Vec<String>,
) -> Result<[DVec3; 2]> {
    let first = &slices[0];
    let Some(orient) = first.plane.orientation else {
        if slices.len() == 1 {
            notes.push("no ImageOrientationPatient: axial orientation assumed".into());
            return Ok([DVec3::X, DVec3::Y]);
        }
        return Err(Error::format(
            &headers[first.file].path,
            format!(
                "{}: ImageOrientationPatient is missing",
                slice_label(headers, first)
            ),
        ));
    };
    for s in slices {
        let same = s.plane.orientation.is_some_and(|o| {
            (o[0] - orient[0]).abs().max_element() <= COSINE_TOL
                && (o[1] - orient[1]).abs().max_element() <= COSINE_TOL
        });
        if !same {
            return Err(Error::format(
                &headers[s.file].path,
                format!(
                    "{}: ImageOrientationPatient differs from {} in the same series (slices are not parallel)",
                    slice_label(headers, s),
                    slice_label(headers, first)
                ),
            ));
        }
    }
    Ok(orient)
}

/// "gantry tilt of 18.5°" when the positions step off the normal, for messages.
fn tilt_note(headers: &[Header], steps: &[DVec3], normal: DVec3) -> Option<String> {
    let mean = steps.iter().copied().sum::<DVec3>() / steps.len().max(1) as f64;
    let along = mean.dot(normal);
    let off = (mean - normal * along).length();
    let angle = off.atan2(along.abs()).to_degrees();
    let recorded = headers[0].gantry_tilt_deg.filter(|t| t.abs() > 0.01);
    if angle > 0.05 {
        Some(format!("a gantry tilt of {angle:.1}°"))
    } else {
        recorded.map(|t| format!("a recorded gantry tilt of {t}°"))
    }
}

/// Every gap along the normal must equal the typical one: a duplicate position, a missing
/// slice or an uneven gap is an error naming the two slices around it.
fn check_gaps(
    headers: &[Header],
    slices: &[SliceRef],
    gaps: &[f64],
    tilt: Option<&str>,
) -> Result<()> {
    let mut sorted = gaps.to_vec();
    sorted.sort_by(f64::total_cmp);
    let typical = sorted[sorted.len() / 2];
    let tol = GAP_TOL_MM.max(GAP_TOL_REL * typical);
    let z = |s: &SliceRef| s.plane.position.unwrap_or_default();
    let normal_z = |k: usize, n: DVec3| z(&slices[k]).dot(n);
    let orient = slices[0].plane.orientation.unwrap_or([DVec3::X, DVec3::Y]);
    let normal = orient[0].cross(orient[1]);
    let bad: Vec<usize> = (0..gaps.len())
        .filter(|&k| (gaps[k] - typical).abs() > tol || gaps[k] <= tol)
        .collect();
    // Report a duplicate first (the most specific problem), else the worst gap.
    let duplicate = bad.iter().copied().find(|&k| gaps[k] <= tol);
    let worst = bad.iter().copied().max_by(|&a, &b| {
        (gaps[a] - typical)
            .abs()
            .total_cmp(&(gaps[b] - typical).abs())
    });
    let Some(k) = duplicate.or(worst) else {
        return Ok(());
    };
    let (a, b) = (
        slice_label(headers, &slices[k]),
        slice_label(headers, &slices[k + 1]),
    );
    let (za, zb) = (normal_z(k, normal), normal_z(k + 1, normal));
    let gap = gaps[k];
    let mut msg = if gap <= tol {
        format!("two slices at the same position ({za:.2} mm along the slice normal): {a} and {b}")
    } else if typical > tol
        && (gap / typical).round() >= 2.0
        && (gap - (gap / typical).round() * typical).abs() <= tol * 2.0
    {
        let missing = (gap / typical).round() as usize - 1;
        format!(
            "{missing} slice(s) missing: gap of {gap:.2} mm between {a} ({za:.2} mm along the slice normal) and {b} ({zb:.2} mm), where the other slices are {typical:.2} mm apart"
        )
    } else {
        format!(
            "uneven slice gaps: {gap:.2} mm between {a} ({za:.2} mm along the slice normal) and {b} ({zb:.2} mm), but {typical:.2} mm between most slices"
        )
    };
    if bad.len() > 1 {
        msg.push_str(&format!(" ({} irregular gaps in all)", bad.len()));
    }
    if let Some(t) = tilt {
        msg.push_str(&format!("; the series also has {t}"));
    }
    msg.push_str("; a volume needs evenly spaced slices");
    Err(Error::format(&headers[slices[k + 1].file].path, msg))
}

/// With uniform gaps, the in-plane part of each step must be the same too (a constant tilt);
/// anything else means the slices do not lie on one straight line.
fn check_straight_line(
    headers: &[Header],
    slices: &[SliceRef],
    steps: &[DVec3],
    drift: DVec3,
    normal: DVec3,
    dz: f64,
) -> Result<()> {
    let tol = GAP_TOL_MM.max(GAP_TOL_REL * dz);
    for (k, s) in steps.iter().enumerate() {
        let off = *s - normal * s.dot(normal);
        if (off - drift).length() > tol {
            return Err(Error::format(
                &headers[slices[k + 1].file].path,
                format!(
                    "slice positions do not lie on a straight line: {} is offset by {:.2} mm within its plane from where {} predicts",
                    slice_label(headers, &slices[k + 1]),
                    (off - drift).length(),
                    slice_label(headers, &slices[k])
                ),
            ));
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Pixel pass
// ---------------------------------------------------------------------------------------------

/// Loads the chosen files as one volume.
fn load_series(headers: Vec<Header>) -> Result<Loaded> {
    let stack = build_stack(&headers)?;
    let first = &headers[0];
    for h in &headers[1..] {
        if h.pixel != first.pixel {
            return Err(Error::format(
                &h.path,
                format!(
                    "pixel layout {:?} differs from {} ({:?}) in the same series",
                    h.pixel,
                    file_name(&first.path),
                    first.pixel
                ),
            ));
        }
    }
    let mut notes = stack.notes;
    let mut data = read_slices(&headers, &stack.slices, stack.geometry.dims)?;
    let mut geometry = stack.geometry;
    if let Some(shear) = stack.shear {
        let (g, d, note) = correct_tilt(&geometry, &data, shear).map_err(super::at(&first.path))?;
        geometry = g;
        data = d;
        notes.push(note);
    }
    let transfer_syntaxes = transfer_syntax_names(&headers);
    if headers.iter().any(|h| h.lossy || is_lossy(&h.ts_uid)) {
        notes.push("pixel data is lossy-compressed: HU values carry the compression error".into());
    }
    let coarsest = stack
        .slices
        .iter()
        .map(|s| s.plane.rescale.slope.abs())
        .fold(0.0, f64::max);
    if coarsest > 1.5 {
        notes.push(format!(
            "RescaleSlope {coarsest}: HU come in steps of {coarsest:.1} ({}-bit stored values)",
            first.pixel.bits_stored
        ));
    }
    let volume = Volume::from_vec(geometry, data).map_err(super::at(&first.path))?;
    let position = first.position.as_deref().filter(|p| !p.trim().is_empty());
    let known = position.and_then(voyage_core::PatientPosition::parse);
    if let (Some(code), None) = (position, known) {
        notes.push(format!("PatientPosition {code:?} is not one of HFS, HFP, FFS, FFP, HFDR, HFDL, FFDR, FFDL: ignored"));
    }
    let meta = Meta {
        format: Some(Format::Dicom),
        modality: first.modality.clone(),
        series_uid: (!first.series_uid.is_empty()).then(|| first.series_uid.clone()),
        series_description: first.series_description.clone(),
        series_number: first.series_number,
        exam_date: first.exam_date.clone(),
        transfer_syntaxes,
        files: headers.len(),
        other_series: Vec::new(),
        warnings: stack.warnings,
        notes,
        position: known,
    };
    Ok(Loaded { volume, meta })
}

fn transfer_syntax_names(headers: &[Header]) -> Vec<String> {
    let mut names: Vec<String> = Vec::new();
    for h in headers {
        let name = ts_name(&h.ts_uid);
        if !names.contains(&name) {
            names.push(name);
        }
    }
    names
}

fn ts_name(uid: &str) -> String {
    TransferSyntaxRegistry
        .get(uid)
        .map(|ts| ts.name().to_string())
        .unwrap_or_else(|| uid.to_string())
}

/// Transfer syntaxes that are, or may be, lossy: JPEG baseline/extended/progressive, JPEG-LS
/// near-lossless, JPEG 2000 and HTJ2K (lossy allowed), JPEG XL.
fn is_lossy(uid: &str) -> bool {
    matches!(
        uid,
        "1.2.840.10008.1.2.4.50"
            | "1.2.840.10008.1.2.4.51"
            | "1.2.840.10008.1.2.4.53"
            | "1.2.840.10008.1.2.4.55"
            | "1.2.840.10008.1.2.4.81"
            | "1.2.840.10008.1.2.4.91"
            | "1.2.840.10008.1.2.4.203"
            | "1.2.840.10008.1.2.4.111"
            | "1.2.840.10008.1.2.4.112"
    )
}

/// Decodes every slice into HU, slice k into `data[k·nx·ny ..]`. Files of one frame are
/// decoded in parallel; a multi-frame file is decoded once and its frames spread.
fn read_slices(headers: &[Header], slices: &[SliceRef], dims: [usize; 3]) -> Result<Vec<i16>> {
    let plane = dims[0] * dims[1];
    let mut data = vec![0i16; plane * dims[2]];
    if headers.iter().all(|h| h.frames == 1) {
        // Collected rather than short-circuited, so that the error reported is always the one
        // of the first bad slice, whatever the thread timing.
        let results: Vec<Result<()>> = data
            .par_chunks_mut(plane)
            .zip(slices.par_iter())
            .map(|(out, s)| {
                let h = &headers[s.file];
                let raw = read_pixel_data(h)?;
                convert_frame(h, &raw, 0, s.plane.rescale, out)
            })
            .collect();
        results.into_iter().collect::<Result<()>>()?;
        return Ok(data);
    }
    for (file, h) in headers.iter().enumerate() {
        let raw = read_pixel_data(h)?;
        data.par_chunks_mut(plane)
            .zip(slices.par_iter())
            .filter(|(_, s)| s.file == file)
            .try_for_each(|(out, s)| convert_frame(h, &raw, s.frame, s.plane.rescale, out))?;
    }
    Ok(data)
}

/// Pixel data as the parser or codec delivers it.
enum Raw {
    /// 16-bit words in host order (native OW data, already byte-swapped for big endian).
    Words(Vec<u16>),
    /// Bytes from `start` on: 8-bit samples, or 16-bit samples little endian (codec output,
    /// OB data, or a whole file read by the fast path).
    Bytes(Vec<u8>, usize),
}

impl Raw {
    fn byte_len(&self) -> usize {
        match self {
            Raw::Words(w) => w.len() * 2,
            Raw::Bytes(b, start) => b.len() - start,
        }
    }
}

/// Reads a whole file and returns its pixel data, decoded if encapsulated.
fn read_pixel_data(h: &Header) -> Result<Raw> {
    let path = &h.path;
    let name = ts_name(&h.ts_uid);
    let expected = h.rows * h.cols * h.frames * h.pixel.bytes_per_sample();
    if let Some(raw) = native_fast_path(h, expected)? {
        return Ok(raw);
    }
    if h.ts_uid == "1.2.840.10008.1.2.4.51" && h.pixel.bits_stored > 8 {
        return Err(Error::format(
            path,
            format!(
                "cannot decode pixel data (transfer syntax {name}): {}-bit lossy JPEG is not supported by the built-in JPEG decoder (8-bit only)",
                h.pixel.bits_stored
            ),
        ));
    }
    let raw = guarded(path, &format!("decoding pixel data ({name})"), || {
        let mut obj = match open_dicom(path, None) {
            Ok(obj) => obj,
            Err(OpenError::Truncated { declared, found }) if declared as usize >= expected => {
                return Err(Error::format(
                    path,
                    format!(
                        "pixel data truncated: its element announces {declared} bytes and the file holds {found} after it (the image needs {expected})"
                    ),
                ));
            }
            Err(e) => return Err(e.into_error(path, "pixel data unreadable")),
        };
        extract_pixels(path, &mut obj, &h.ts_uid, &name)
    })?;
    if raw.byte_len() < expected {
        return Err(Error::format(
            path,
            format!(
                "pixel data truncated: expected {expected} bytes, found {} ({name})",
                raw.byte_len()
            ),
        ));
    }
    Ok(raw)
}

/// Uncompressed little endian files whose pixel data is the last element (nearly all): the
/// file is read in one go and the pixel bytes taken from its end, without parsing the data set
/// again. The element header in front of them is checked exactly (tag, VR, length = what the
/// header promises); anything else returns `None` and goes the general way.
fn native_fast_path(h: &Header, expected: usize) -> Result<Option<Raw>> {
    let explicit = match h.ts_uid.as_str() {
        "1.2.840.10008.1.2.1" => true,
        "1.2.840.10008.1.2" => false,
        _ => return Ok(None),
    };
    let mut bytes = std::fs::read(&h.path).map_err(|e| Error::io(&h.path, e))?;
    let value_len = expected + expected % 2;
    let header_len = if explicit { 12 } else { 8 };
    let Some(start) = bytes.len().checked_sub(value_len + header_len) else {
        return Ok(None);
    };
    let head = &bytes[start..start + header_len];
    let declared = u32::from_le_bytes([
        head[header_len - 4],
        head[header_len - 3],
        head[header_len - 2],
        head[header_len - 1],
    ]);
    let tag_ok = head[..4] == [0xE0, 0x7F, 0x10, 0x00];
    let vr_ok = !explicit || matches!(&head[4..8], b"OW\0\0" | b"OB\0\0");
    if !(tag_ok && vr_ok && declared as usize == value_len) {
        return Ok(None);
    }
    bytes.truncate(start + header_len + expected);
    Ok(Some(Raw::Bytes(bytes, start + header_len)))
}

fn extract_pixels(
    path: &Path,
    obj: &mut DefaultDicomObject,
    ts_uid: &str,
    name: &str,
) -> Result<Raw> {
    let decode_error = |why: String| {
        Error::format(
            path,
            format!("cannot decode pixel data (transfer syntax {name}): {why}"),
        )
    };
    let Some(ts) = TransferSyntaxRegistry.get(ts_uid) else {
        return Err(decode_error(format!(
            "unknown transfer syntax UID {ts_uid}"
        )));
    };
    let Some(elem) = obj.get(tags::PIXEL_DATA) else {
        return Err(Error::format(
            path,
            "no pixel data (7FE0,0010) in this file",
        ));
    };
    match elem.value() {
        Value::PixelSequence(seq) if ts_uid == RLE_LOSSLESS => {
            let shape = RleShape::of(obj).map_err(decode_error)?;
            decode_rle(seq.fragments(), shape)
                .map(|b| Raw::Bytes(b, 0))
                .map_err(decode_error)
        }
        Value::PixelSequence(_) => {
            let Some(reader) = ts.pixel_data_reader() else {
                return Err(decode_error(
                    "no decoder for this transfer syntax is built in".into(),
                ));
            };
            let mut out = Vec::new();
            reader
                .decode(&*obj, &mut out)
                .map_err(|e| decode_error(error_chain(&e)))?;
            Ok(Raw::Bytes(out, 0))
        }
        Value::Primitive(_) => {
            let elem = obj
                .take(tags::PIXEL_DATA)
                .ok_or_else(|| decode_error("pixel data vanished".into()))?;
            match elem.into_value() {
                Value::Primitive(PrimitiveValue::U16(w)) => Ok(Raw::Words(w.into_vec())),
                Value::Primitive(PrimitiveValue::U8(b))
                    if ts.endianness() == Endianness::Little =>
                {
                    Ok(Raw::Bytes(b.into_vec(), 0))
                }
                Value::Primitive(PrimitiveValue::U8(b)) => Ok(Raw::Words(
                    b.chunks_exact(2)
                        .map(|c| u16::from_be_bytes([c[0], c[1]]))
                        .collect(),
                )),
                Value::Primitive(PrimitiveValue::Empty) => {
                    Err(Error::format(path, "pixel data (7FE0,0010) is empty"))
                }
                _ => Err(decode_error(
                    "pixel data has an unexpected value representation".into(),
                )),
            }
        }
        Value::Sequence(_) => Err(decode_error(
            "pixel data is a sequence, not pixel values".into(),
        )),
    }
}

const RLE_LOSSLESS: &str = "1.2.840.10008.1.2.5";

/// What an RLE frame decodes to.
#[derive(Clone, Copy)]
struct RleShape {
    pixels: usize,
    bytes_per_sample: usize,
    frames: usize,
}

impl RleShape {
    fn of(obj: &DefaultDicomObject) -> std::result::Result<RleShape, String> {
        let get = |tag: Tag, name: &str| uint(obj, tag, name);
        let rows = get(tags::ROWS, "Rows")?.ok_or("no Rows")? as usize;
        let cols = get(tags::COLUMNS, "Columns")?.ok_or("no Columns")? as usize;
        let bits = get(tags::BITS_ALLOCATED, "BitsAllocated")?.ok_or("no BitsAllocated")?;
        let samples = get(tags::SAMPLES_PER_PIXEL, "SamplesPerPixel")?.unwrap_or(1);
        let frames = get(tags::NUMBER_OF_FRAMES, "NumberOfFrames")?
            .unwrap_or(1)
            .max(1) as usize;
        if samples != 1 || !(bits == 8 || bits == 16) {
            return Err(format!(
                "RLE with {samples} samples of {bits} bits is not a CT image"
            ));
        }
        Ok(RleShape {
            pixels: rows * cols,
            bytes_per_sample: bits as usize / 8,
            frames,
        })
    }
}

/// DICOM RLE Lossless (PS3.5 Annex G), grayscale: per frame a 64-byte header (segment count,
/// offsets), then one PackBits segment per byte of the sample, most significant first. Decoded
/// here, with every length checked, into little-endian samples: dicom-rs's decoder indexes past
/// its buffer when a segment decodes short (found by fuzzing).
fn decode_rle(fragments: &[Vec<u8>], shape: RleShape) -> std::result::Result<Vec<u8>, String> {
    // The first fragment may be the basic offset table's successor; frames are the fragments.
    if fragments.len() != shape.frames {
        return Err(format!(
            "{} fragments for {} frames (frames split over fragments are not supported)",
            fragments.len(),
            shape.frames
        ));
    }
    let bps = shape.bytes_per_sample;
    let mut out = vec![0u8; shape.frames * shape.pixels * bps];
    for (f, frame) in fragments.iter().enumerate() {
        if frame.len() < 64 {
            return Err(format!("RLE frame {f} has no 64-byte header"));
        }
        let word = |i: usize| {
            u32::from_le_bytes([
                frame[4 * i],
                frame[4 * i + 1],
                frame[4 * i + 2],
                frame[4 * i + 3],
            ]) as usize
        };
        let segments = word(0);
        if segments != bps {
            return Err(format!(
                "RLE frame {f} has {segments} segments, expected {bps}"
            ));
        }
        let dst = &mut out[f * shape.pixels * bps..(f + 1) * shape.pixels * bps];
        for seg in 0..segments {
            let start = word(1 + seg);
            let end = if seg + 1 < segments {
                word(2 + seg)
            } else {
                frame.len()
            };
            if start < 64 || start > end || end > frame.len() {
                return Err(format!(
                    "RLE frame {f} segment {seg} spans bytes {start}..{end} of {}",
                    frame.len()
                ));
            }
            // Segment 0 holds the most significant bytes; samples are stored little-endian.
            let byte = bps - 1 - seg;
            unpack_bits(&frame[start..end], shape.pixels, |i, v| {
                dst[i * bps + byte] = v
            })
            .map_err(|n| {
                format!(
                    "RLE frame {f} segment {seg} decodes to {n} bytes, expected {}",
                    shape.pixels
                )
            })?;
        }
    }
    Ok(out)
}

/// PackBits: a control byte n ≥ 0 copies the next n + 1 bytes, n in −127..=−1 repeats the next
/// byte 1 − n times, −128 does nothing. Calls `put(i, byte)` for each of the first `want`
/// bytes; returns how many there were when that is fewer.
fn unpack_bits(
    src: &[u8],
    want: usize,
    mut put: impl FnMut(usize, u8),
) -> std::result::Result<(), usize> {
    let (mut i, mut n) = (0usize, 0usize);
    while i < src.len() && n < want {
        let c = src[i] as i8;
        i += 1;
        if c >= 0 {
            let len = c as usize + 1;
            for &b in src.get(i..i + len).ok_or(n)?.iter().take(want - n) {
                put(n, b);
                n += 1;
            }
            i += len;
        } else if c != -128 {
            let b = *src.get(i).ok_or(n)?;
            i += 1;
            for _ in 0..(1 - c as isize) as usize {
                if n == want {
                    break;
                }
                put(n, b);
                n += 1;
            }
        }
    }
    if n < want { Err(n) } else { Ok(()) }
}

/// Turns frame `frame` of a file's pixel data into HU: mask to BitsStored, extend the sign,
/// apply this slice's rescale, round and saturate.
fn convert_frame(
    h: &Header,
    raw: &Raw,
    frame: usize,
    rescale: Rescale,
    out: &mut [i16],
) -> Result<()> {
    let n = h.rows * h.cols;
    let f = h.pixel;
    let unpack = Unpack::new(f);
    let hu = Hu::new(rescale);
    match (raw, f.bits_allocated) {
        (Raw::Words(w), 16) => convert(
            w[frame * n..(frame + 1) * n].iter().map(|&v| u32::from(v)),
            unpack,
            hu,
            out,
        ),
        (Raw::Bytes(b, start), 16) => {
            let b = &b[start + frame * n * 2..start + (frame + 1) * n * 2];
            convert(
                b.as_chunks::<2>()
                    .0
                    .iter()
                    .map(|c| u32::from(u16::from_le_bytes(*c))),
                unpack,
                hu,
                out,
            )
        }
        (Raw::Bytes(b, start), 8) => convert(
            b[start + frame * n..start + (frame + 1) * n]
                .iter()
                .map(|&v| u32::from(v)),
            unpack,
            hu,
            out,
        ),
        (Raw::Words(w), 8) => {
            // 8-bit samples read as OW words (implicit VR): two samples per word, low byte first.
            let start = frame * n;
            let byte = |i: usize| {
                u32::from(if i.is_multiple_of(2) {
                    w[i / 2] & 0xFF
                } else {
                    w[i / 2] >> 8
                })
            };
            convert((start..start + n).map(byte), unpack, hu, out)
        }
        _ => {
            return Err(Error::format(
                &h.path,
                format!("BitsAllocated {} is not supported", f.bits_allocated),
            ));
        }
    }
    Ok(())
}

/// How to get the stored value out of an allocated sample: shift away the bits below
/// HighBit−BitsStored+1, mask to BitsStored (higher bits may hold overlays or garbage) and, for
/// signed data, extend the sign.
#[derive(Clone, Copy)]
struct Unpack {
    shift: u32,
    mask: u32,
    /// 32 − BitsStored: shifting left then arithmetic-right by this extends the sign.
    sign_shift: u32,
    signed: bool,
}

impl Unpack {
    fn new(f: PixelFormat) -> Self {
        let bits = u32::from(f.bits_stored);
        Unpack {
            shift: u32::from(f.high_bit) + 1 - bits,
            mask: ((1u64 << bits) - 1) as u32,
            sign_shift: 32 - bits,
            signed: f.signed,
        }
    }
}

/// Stored value → HU with saturation. Integer arithmetic when the slope is 1 and the intercept
/// whole (the usual CT case): exact and cheap.
#[derive(Clone, Copy)]
struct Hu {
    slope: f64,
    intercept: f64,
    integer_intercept: Option<i32>,
}

impl Hu {
    fn new(r: Rescale) -> Self {
        let whole = r.slope == 1.0 && r.intercept.fract() == 0.0 && r.intercept.abs() < 1e6;
        Hu {
            slope: r.slope,
            intercept: r.intercept,
            integer_intercept: whole.then_some(r.intercept as i32),
        }
    }
}

/// The conversion loop, specialised outside the loop on the bit layout and on integer rescale
/// so that the body is branch-free and free of overflow checks (it vectorises in optimised
/// builds): this is most of the CPU time of loading an uncompressed series.
#[inline(always)]
fn convert(src: impl Iterator<Item = u32>, u: Unpack, hu: Hu, out: &mut [i16]) {
    let (shift, mask, ss) = (u.shift, u.mask, u.sign_shift);
    let full16 = shift == 0 && mask == 0xFFFF;
    match (u.signed, full16) {
        (true, true) => rescale_all(src.map(|v| i32::from(v as u16 as i16)), hu, out),
        (false, true) => rescale_all(src.map(|v| (v & 0xFFFF) as i32), hu, out),
        (true, false) => rescale_all(
            src.map(move |v| ((((v >> shift) & mask) << ss) as i32) >> ss),
            hu,
            out,
        ),
        (false, false) => rescale_all(src.map(move |v| ((v >> shift) & mask) as i32), hu, out),
    }
}

#[inline(always)]
fn rescale_all(src: impl Iterator<Item = i32>, hu: Hu, out: &mut [i16]) {
    const LO: i32 = i16::MIN as i32;
    const HI: i32 = i16::MAX as i32;
    match hu.integer_intercept {
        // |stored| < 2^16 and |intercept| < 10^6: the sum cannot overflow.
        Some(c) => out
            .iter_mut()
            .zip(src)
            .for_each(|(o, x)| *o = x.wrapping_add(c).clamp(LO, HI) as i16),
        None => {
            let (slope, intercept) = (hu.slope, hu.intercept);
            // Round half away from zero like f64::round, without a libm call; `as` saturates.
            out.iter_mut().zip(src).for_each(|(o, x)| {
                let y = f64::from(x) * slope + intercept;
                *o = ((y + 0.5f64.copysign(y)) as i32).clamp(LO, HI) as i16;
            })
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Gantry tilt correction
// ---------------------------------------------------------------------------------------------

/// Undoes a constant in-plane drift of the slices (gantry tilt): slice k is shifted by
/// `-k·shear` within its plane, with linear interpolation, onto a grid widened so that every
/// acquired voxel is kept. The result is orthogonal, with k along the slice normal.
fn correct_tilt(
    g: &Geometry,
    data: &[i16],
    shear: [f64; 2],
) -> Result<(Geometry, Vec<i16>, String)> {
    let [nx, ny, nz] = g.dims;
    let last = (nz - 1) as f64;
    // Extent of the drift over the stack, in voxels along i and j.
    let lo = [
        0.0f64.min(shear[0] * last / g.spacing[0]),
        0.0f64.min(shear[1] * last / g.spacing[1]),
    ];
    let hi = [
        0.0f64.max(shear[0] * last / g.spacing[0]),
        0.0f64.max(shear[1] * last / g.spacing[1]),
    ];
    let grow = [
        (hi[0] - lo[0] - 1e-6).ceil().max(0.0) as usize,
        (hi[1] - lo[1] - 1e-6).ceil().max(0.0) as usize,
    ];
    let dims = [nx + grow[0], ny + grow[1], nz];
    check_dims(dims.map(|d| d as u64))?;
    let mut out_geom = g.clone();
    out_geom.dims = dims;
    let m = g.direction_mat();
    let origin = DVec3::from_array(g.origin)
        + m.col(0) * (lo[0] * g.spacing[0])
        + m.col(1) * (lo[1] * g.spacing[1]);
    out_geom.origin = origin.to_array();
    let out_plane = dims[0] * dims[1];
    let mut out = vec![OUTSIDE_HU; out_plane * nz];
    out.par_chunks_mut(out_plane)
        .enumerate()
        .for_each(|(k, dst)| {
            // Output voxel (i', j') of slice k samples input (i' + off_i, j' + off_j).
            let off = [
                lo[0] - k as f64 * shear[0] / g.spacing[0],
                lo[1] - k as f64 * shear[1] / g.spacing[1],
            ];
            let src = &data[k * nx * ny..(k + 1) * nx * ny];
            shift_slice(src, [nx, ny], dst, [dims[0], dims[1]], off);
        });
    let along = g.spacing[2];
    let drift = (shear[0] * shear[0] + shear[1] * shear[1]).sqrt();
    let note = format!(
        "gantry tilt of {:.1}° corrected: slices shifted within their planes by up to {:.1} mm (linear interpolation); grid widened to {}×{}, uncovered voxels set to {OUTSIDE_HU} HU",
        drift.atan2(along).to_degrees(),
        drift * last,
        dims[0],
        dims[1]
    );
    Ok((out_geom, out, note))
}

/// Bilinear resampling of one slice by a constant offset (the weights are the same for every
/// voxel); samples outside the source keep the destination's fill value.
fn shift_slice(
    src: &[i16],
    [sx, sy]: [usize; 2],
    dst: &mut [i16],
    [dx, dy]: [usize; 2],
    off: [f64; 2],
) {
    let (fi, fj) = (off[0].floor(), off[1].floor());
    let (wi, wj) = (off[0] - fi, off[1] - fj);
    let (fi, fj) = (fi as isize, fj as isize);
    let at = |i: isize, j: isize| -> Option<f64> {
        (i >= 0 && j >= 0 && (i as usize) < sx && (j as usize) < sy)
            .then(|| f64::from(src[i as usize + sx * j as usize]))
    };
    for j in 0..dy {
        let j0 = j as isize + fj;
        for i in 0..dx {
            let i0 = i as isize + fi;
            let corners = [
                (at(i0, j0), (1.0 - wi) * (1.0 - wj)),
                (at(i0 + 1, j0), wi * (1.0 - wj)),
                (at(i0, j0 + 1), (1.0 - wi) * wj),
                (at(i0 + 1, j0 + 1), wi * wj),
            ];
            let (mut sum, mut weight) = (0.0, 0.0);
            for (v, w) in corners {
                if let Some(v) = v
                    && w > 0.0
                {
                    sum += v * w;
                    weight += w;
                }
            }
            // Keep the fill value unless the sample is mostly inside the acquired slice.
            if weight >= 0.5 {
                dst[i + dx * j] = (sum / weight).round() as i16;
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Lenient opening
// ---------------------------------------------------------------------------------------------

/// Why [`open_dicom`] failed.
enum OpenError {
    Io(std::io::Error),
    /// The file meta information (group 0002) is unusable; the message says why.
    Meta(String),
    /// The top-level pixel data element announces more bytes than the file has left.
    Truncated {
        declared: u32,
        found: u64,
    },
    /// dicom-rs could not parse the data set.
    Parse(dicom_object::ReadError),
}

impl OpenError {
    fn into_error(self, path: &Path, what: &str) -> Error {
        match self {
            OpenError::Io(e) => Error::io(path, e),
            OpenError::Meta(m) => Error::format(path, format!("{what}: {m}")),
            OpenError::Truncated { declared, found } => Error::format(
                path,
                format!(
                    "pixel data truncated: the element announces {declared} bytes, found {found}"
                ),
            ),
            OpenError::Parse(e) if ends_early(&e) => Error::format(
                path,
                format!(
                    "{what}: the file is cut short (truncated): {}",
                    error_chain(&e)
                ),
            ),
            OpenError::Parse(e) => Error::format(path, format!("{what}: {}", error_chain(&e))),
        }
    }
}

/// Whether an error was caused by the data ending before a value it announced.
fn ends_early(e: &(dyn std::error::Error + 'static)) -> bool {
    let mut cur: Option<&(dyn std::error::Error + 'static)> = Some(e);
    while let Some(err) = cur {
        if err
            .downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::UnexpectedEof)
        {
            return true;
        }
        cur = err.source();
    }
    false
}

/// The largest file meta group accepted (real ones are a few hundred bytes).
const MAX_META_BYTES: usize = 1 << 20;

/// Opens a DICOM Part 10 file, reading up to (not including) `until` when given.
///
/// The file meta group is parsed here and handed to dicom-rs rewritten, because real files
/// often break rules that dicom-rs enforces there: a missing group length, an application
/// entity title longer than 16 characters (the transfer-syntax test files have one), padding
/// in the wrong place. Only the elements needed to read the data set are kept.
fn open_dicom(
    path: &Path,
    until: Option<Tag>,
) -> std::result::Result<DefaultDicomObject, OpenError> {
    use std::io::{Cursor, Read};
    let mut file = std::fs::File::open(path).map_err(OpenError::Io)?;
    let mut buf = Vec::with_capacity(8192);
    let mut eof = false;
    let meta = loop {
        match parse_meta(&buf, eof) {
            Ok(Some(meta)) => break meta,
            Ok(None) => {
                if buf.len() >= MAX_META_BYTES {
                    return Err(OpenError::Meta(
                        "the file meta information is implausibly large".into(),
                    ));
                }
                let want = (buf.len().max(4096) * 2).min(MAX_META_BYTES) - buf.len();
                let got = (&mut file)
                    .take(want as u64)
                    .read_to_end(&mut buf)
                    .map_err(OpenError::Io)?;
                eof = got < want;
            }
            Err(m) => return Err(OpenError::Meta(m)),
        }
    };
    if TransferSyntaxRegistry.get(&meta.ts_uid).is_none() {
        return Err(OpenError::Meta(format!(
            "cannot decode pixel data (transfer syntax {}): not supported by voyage's DICOM reader",
            describe_unknown_ts(&meta.ts_uid)
        )));
    }
    if meta.ts_uid == DEFLATED_EXPLICIT_LE {
        return open_deflated(meta, buf, file, until);
    }
    // Where the header pass stops: the top-level pixel data, as the walk found it. dicom-rs is
    // given the bytes before it only, so that a reader that disagrees with the walk on where
    // a sequence ends cannot go on to read (and allocate) the pixel data.
    let mut header_end = None;
    if let Some(layout) = Layout::of(&meta.ts_uid) {
        let size = file.metadata().map_err(OpenError::Io)?.len();
        loop {
            match scan_lengths(&buf, meta.end, size, layout, until.is_none()) {
                Scan::Sound { pixel_data } => {
                    header_end = pixel_data;
                    break;
                }
                Scan::NeedMore(upto) if !eof && (buf.len() as u64) < size => {
                    let want = upto.max(buf.len() * 2).min(size as usize) - buf.len();
                    let got = (&mut file)
                        .take(want as u64)
                        .read_to_end(&mut buf)
                        .map_err(OpenError::Io)?;
                    eof = got < want;
                }
                // Cut short within the header: dicom-rs reports where.
                Scan::NeedMore(_) => break,
                // The header pass stops before the pixel data; the pixel pass reports this.
                Scan::Truncated { at, .. } if until.is_some() => {
                    header_end = Some(at);
                    break;
                }
                Scan::Truncated {
                    declared, found, ..
                } => {
                    return Err(OpenError::Truncated { declared, found });
                }
                Scan::Bad(m) => return Err(OpenError::Meta(m)),
            }
        }
    }
    let rest = match header_end {
        Some(at) => {
            buf.truncate(at);
            0
        }
        None => u64::MAX,
    };
    let source = Cursor::new(meta.clean)
        .chain(Cursor::new(buf.split_off(meta.end)))
        .chain(file.take(rest));
    let mut options = OpenFileOptions::new().read_preamble(dicom_object::file::ReadPreamble::Never);
    if let Some(tag) = until {
        options = options.read_until(tag);
    }
    options.from_reader(source).map_err(OpenError::Parse)
}

/// The file meta group as found, and rewritten.
struct MetaGroup {
    /// "DICM" followed by a clean, explicit VR little endian meta group.
    clean: Vec<u8>,
    /// Offset in the file where the data set starts.
    end: usize,
    ts_uid: String,
}

const DEFLATED_EXPLICIT_LE: &str = "1.2.840.10008.1.2.1.99";
const EXPLICIT_LE: &str = "1.2.840.10008.1.2.1";

/// A deflated data set holds at most this many times its compressed size (real ones: 2–10×);
/// more is a corrupt or hostile stream, refused before it fills the memory.
const MAX_INFLATE_RATIO: u64 = 256;

/// Deflated explicit VR little endian: inflated here (bounded), its lengths checked like any
/// other data set's, and handed to dicom-rs as plain explicit VR little endian. dicom-rs would
/// otherwise inflate as it parses and allocate whatever a corrupt length inside announces.
fn open_deflated(
    meta: MetaGroup,
    mut buf: Vec<u8>,
    mut file: std::fs::File,
    until: Option<Tag>,
) -> std::result::Result<DefaultDicomObject, OpenError> {
    use std::io::{Cursor, Read};
    file.read_to_end(&mut buf).map_err(OpenError::Io)?;
    let compressed = &buf[meta.end.min(buf.len())..];
    let cap = (compressed.len() as u64)
        .saturating_mul(MAX_INFLATE_RATIO)
        .max(1 << 20);
    let mut inflated = Vec::new();
    flate2::read::DeflateDecoder::new(compressed)
        .take(cap + 1)
        .read_to_end(&mut inflated)
        .map_err(|e| OpenError::Meta(format!("the deflated data set cannot be inflated: {e}")))?;
    if inflated.len() as u64 > cap {
        return Err(OpenError::Meta(format!(
            "the deflated data set inflates to more than {MAX_INFLATE_RATIO} times its size"
        )));
    }
    let layout = Layout {
        explicit: true,
        big_endian: false,
    };
    match scan_lengths(&inflated, 0, inflated.len() as u64, layout, until.is_none()) {
        Scan::Sound { .. } | Scan::NeedMore(_) => {}
        Scan::Truncated { .. } if until.is_some() => {}
        Scan::Truncated {
            declared, found, ..
        } => {
            return Err(OpenError::Truncated { declared, found });
        }
        Scan::Bad(m) => return Err(OpenError::Meta(m)),
    }
    let clean = with_transfer_syntax(&meta.clean, EXPLICIT_LE);
    let source = Cursor::new(clean).chain(Cursor::new(inflated));
    let mut options = OpenFileOptions::new().read_preamble(dicom_object::file::ReadPreamble::Never);
    if let Some(tag) = until {
        options = options.read_until(tag);
    }
    let mut obj = options.from_reader(source).map_err(OpenError::Parse)?;
    // Report the file as it is: deflated.
    obj.meta_mut().transfer_syntax = DEFLATED_EXPLICIT_LE.to_string();
    Ok(obj)
}

/// The rewritten meta group ("DICM" + group length + elements, as `parse_meta` makes it)
/// with another transfer syntax.
fn with_transfer_syntax(clean: &[u8], ts: &str) -> Vec<u8> {
    let mut body = Vec::with_capacity(clean.len());
    let mut pos = 16; // "DICM" and the group length element
    while pos + 8 <= clean.len() {
        let element = u16::from_le_bytes([clean[pos + 2], clean[pos + 3]]);
        let vr = [clean[pos + 4], clean[pos + 5]];
        let (header, len) = if &vr == b"OB" {
            (
                12,
                u32::from_le_bytes([
                    clean[pos + 8],
                    clean[pos + 9],
                    clean[pos + 10],
                    clean[pos + 11],
                ]) as usize,
            )
        } else {
            (
                8,
                u16::from_le_bytes([clean[pos + 6], clean[pos + 7]]) as usize,
            )
        };
        let value = &clean[pos + header..(pos + header + len).min(clean.len())];
        if element == 0x0010 {
            let mut v = ts.as_bytes().to_vec();
            if v.len() % 2 == 1 {
                v.push(0);
            }
            put_meta_element(&mut body, element, &vr, &v);
        } else {
            put_meta_element(&mut body, element, &vr, value);
        }
        pos += header + len;
    }
    let mut out = Vec::with_capacity(body.len() + 16);
    out.extend_from_slice(b"DICM");
    out.extend_from_slice(&[0x02, 0x00, 0x00, 0x00, b'U', b'L', 4, 0]);
    out.extend_from_slice(&(body.len() as u32).to_le_bytes());
    out.extend_from_slice(&body);
    out
}

/// Names for transfer syntaxes that dicom-rs does not know (retired JPEG processes mostly), so
/// that the refusal says what the file is.
fn describe_unknown_ts(uid: &str) -> String {
    let name = match uid {
        "1.2.840.10008.1.2.4.52" | "1.2.840.10008.1.2.4.54" => {
            "JPEG Extended, Non-Hierarchical (retired)"
        }
        "1.2.840.10008.1.2.4.53" => {
            "JPEG Spectral Selection, Non-Hierarchical (Process 6 & 8), retired"
        }
        "1.2.840.10008.1.2.4.55" => {
            "JPEG Full Progression, Non-Hierarchical (Process 10 & 12), retired"
        }
        "1.2.840.10008.1.2.4.56" | "1.2.840.10008.1.2.4.58" => {
            "JPEG Lossless, Non-Hierarchical (retired)"
        }
        u if u.starts_with("1.2.840.10008.1.2.4.") => "a JPEG family syntax unknown to the decoder",
        _ => "unknown",
    };
    format!("{uid}: {name}")
}

/// Parses the file meta group from the start of a file. `Ok(None)` asks for more bytes.
fn parse_meta(buf: &[u8], eof: bool) -> std::result::Result<Option<MetaGroup>, String> {
    let need_more = |eof: bool| {
        if eof {
            Err("the file ends inside its file meta information".to_string())
        } else {
            Ok(None)
        }
    };
    if buf.len() < 132 && !eof {
        return Ok(None);
    }
    let mut pos = if buf.len() >= 132 && &buf[128..132] == b"DICM" {
        132
    } else if buf.len() >= 4 && &buf[0..4] == b"DICM" {
        4
    } else {
        return Err("no 'DICM' marker: not a DICOM Part 10 file".into());
    };
    let mut elements: Vec<(u16, Vec<u8>)> = Vec::new();
    loop {
        if pos + 8 > buf.len() {
            if eof && pos + 2 > buf.len() {
                break; // a file of meta information only
            }
            return need_more(eof);
        }
        let group = u16::from_le_bytes([buf[pos], buf[pos + 1]]);
        if group != 0x0002 {
            break;
        }
        let element = u16::from_le_bytes([buf[pos + 2], buf[pos + 3]]);
        let vr = [buf[pos + 4], buf[pos + 5]];
        if !vr.iter().all(u8::is_ascii_uppercase) {
            return Err(format!(
                "file meta element (0002,{element:04X}) is not explicit VR little endian"
            ));
        }
        let long = matches!(
            &vr,
            b"OB"
                | b"OW"
                | b"OF"
                | b"OD"
                | b"OL"
                | b"OV"
                | b"SQ"
                | b"UT"
                | b"UN"
                | b"UC"
                | b"UR"
                | b"SV"
                | b"UV"
        );
        let (header, len) = if long {
            if pos + 12 > buf.len() {
                return need_more(eof);
            }
            (
                12,
                u32::from_le_bytes([buf[pos + 8], buf[pos + 9], buf[pos + 10], buf[pos + 11]])
                    as usize,
            )
        } else {
            (
                8,
                usize::from(u16::from_le_bytes([buf[pos + 6], buf[pos + 7]])),
            )
        };
        if len == 0xFFFF_FFFF {
            return Err(format!(
                "file meta element (0002,{element:04X}) has an undefined length"
            ));
        }
        if pos + header + len > buf.len() {
            if buf.len() >= MAX_META_BYTES {
                return Err(format!(
                    "file meta element (0002,{element:04X}) is {len} bytes long"
                ));
            }
            return need_more(eof);
        }
        elements.push((element, buf[pos + header..pos + header + len].to_vec()));
        pos += header + len;
    }
    let text = |el: u16| {
        elements.iter().find(|(e, _)| *e == el).map(|(_, v)| {
            String::from_utf8_lossy(v)
                .trim_matches(|c: char| c == '\0' || c.is_whitespace())
                .to_string()
        })
    };
    let ts = text(0x0010)
        .filter(|t| !t.is_empty())
        .ok_or("no TransferSyntaxUID (0002,0010) in the file meta information, so the data set cannot be decoded")?;
    let mut body = Vec::with_capacity(256);
    put_meta_element(&mut body, 0x0001, b"OB", &[0, 1]);
    for (el, value) in [
        (0x0002, text(0x0002)),
        (0x0003, text(0x0003)),
        (0x0010, Some(ts)),
        (0x0012, text(0x0012)),
    ] {
        if let Some(v) = value.filter(|v| !v.is_empty()) {
            let mut bytes = v.into_bytes();
            if bytes.len() % 2 == 1 {
                bytes.push(0);
            }
            put_meta_element(&mut body, el, b"UI", &bytes);
        }
    }
    let mut clean = Vec::with_capacity(body.len() + 16);
    clean.extend_from_slice(b"DICM");
    clean.extend_from_slice(&[0x02, 0x00, 0x00, 0x00, b'U', b'L', 4, 0]);
    clean.extend_from_slice(&(body.len() as u32).to_le_bytes());
    clean.extend_from_slice(&body);
    Ok(Some(MetaGroup {
        clean,
        end: pos,
        ts_uid: text(0x0010).unwrap_or_default(),
    }))
}

fn put_meta_element(out: &mut Vec<u8>, element: u16, vr: &[u8; 2], value: &[u8]) {
    out.extend_from_slice(&0x0002u16.to_le_bytes());
    out.extend_from_slice(&element.to_le_bytes());
    out.extend_from_slice(vr);
    if vr == b"OB" {
        out.extend_from_slice(&[0, 0]);
        out.extend_from_slice(&(value.len() as u32).to_le_bytes());
    } else {
        out.extend_from_slice(&(value.len() as u16).to_le_bytes());
    }
    out.extend_from_slice(value);
}

/// How a data set is encoded, for [`scan_lengths`].
#[derive(Clone, Copy)]
struct Layout {
    explicit: bool,
    big_endian: bool,
}

impl Layout {
    /// `None` for deflated data sets, which cannot be scanned before inflating.
    fn of(ts_uid: &str) -> Option<Layout> {
        let ts = TransferSyntaxRegistry.get(ts_uid)?;
        if matches!(
            ts.codec(),
            dicom_encoding::transfer_syntax::Codec::Dataset(_)
        ) {
            return None;
        }
        Some(Layout {
            explicit: ts_uid != "1.2.840.10008.1.2",
            big_endian: ts.endianness() == Endianness::Big,
        })
    }

    fn u16(&self, b: &[u8]) -> u16 {
        if self.big_endian {
            u16::from_be_bytes([b[0], b[1]])
        } else {
            u16::from_le_bytes([b[0], b[1]])
        }
    }

    fn u32(&self, b: &[u8]) -> u32 {
        if self.big_endian {
            u32::from_be_bytes([b[0], b[1], b[2], b[3]])
        } else {
            u32::from_le_bytes([b[0], b[1], b[2], b[3]])
        }
    }
}

enum Scan {
    /// Every length up to the top-level pixel data (or the end) fits in the file; where the
    /// walk stopped at the pixel data (without `whole`), its offset.
    Sound {
        pixel_data: Option<usize>,
    },
    /// Needs the file's bytes up to this offset.
    NeedMore(usize),
    /// The top-level pixel data, at `at`, announces more than the file holds.
    Truncated {
        declared: u32,
        found: u64,
        at: usize,
    },
    Bad(String),
}

const UNDEFINED: u32 = 0xFFFF_FFFF;
const MAX_NESTING: usize = 64;

/// Walks the element headers of a data set (descending into sequences and items) and checks
/// that every announced length fits in what is left of the file. dicom-rs allocates and zeroes
/// a buffer of the announced length before reading a value, so a corrupt length would
/// otherwise cost gigabytes of memory before the read fails. With `whole`, the walk goes on
/// through the pixel data (each fragment of encapsulated data too) to the end of the file, as
/// the full read will; without, it stops at the pixel data, where the header read stops.
fn scan_lengths(buf: &[u8], start: usize, file_size: u64, layout: Layout, whole: bool) -> Scan {
    // Open containers: `Some(end)` for a defined length, `None` for one closed by a delimiter.
    let mut open: Vec<Option<usize>> = Vec::new();
    let mut pos = start;
    loop {
        while let Some(Some(end)) = open.last() {
            if pos < *end {
                break;
            }
            open.pop();
        }
        if pos as u64 >= file_size {
            return Scan::Sound { pixel_data: None };
        }
        if pos + 8 > buf.len() {
            return Scan::NeedMore(pos + 12);
        }
        let (group, element) = (layout.u16(&buf[pos..]), layout.u16(&buf[pos + 2..]));
        if group == 0xFFFE {
            // Item (E000) opens a container; delimiters (E00D, E0DD) close one; as in dicom-rs,
            // any other (FFFE,xxxx) is a plain element. A delimiter's length should be 0, but
            // dicom-rs reads whatever it declares as a value: bounded by the file here, and
            // stepped over as dicom-rs does.
            let len = layout.u32(&buf[pos + 4..]);
            if let Some(bad) = check_len(group, element, len, pos + 8, file_size) {
                return bad;
            }
            if element == 0xE000 {
                open.push((len != UNDEFINED).then_some(pos + 8 + len as usize));
                pos += 8;
            } else {
                let delimiter = matches!(element, 0xE00D | 0xE0DD);
                if delimiter && open.last().is_some_and(Option::is_none) {
                    open.pop();
                }
                pos += 8 + if len == UNDEFINED { 0 } else { len as usize };
            }
        } else {
            let (header, len, sequence) = match element_header(buf, pos, layout) {
                Some(h) => h,
                None => return Scan::NeedMore(pos + 12),
            };
            let value = pos + header;
            if (group, element) == (0x7FE0, 0x0010) && open.is_empty() {
                let found = file_size.saturating_sub(value as u64);
                if len != UNDEFINED && u64::from(len) > found {
                    return Scan::Truncated {
                        declared: len,
                        found,
                        at: pos,
                    };
                }
                if !whole {
                    return Scan::Sound {
                        pixel_data: Some(pos),
                    };
                }
                if len == UNDEFINED {
                    match scan_fragments(buf, value, file_size, layout) {
                        Ok(after) => {
                            pos = after;
                            continue;
                        }
                        Err(scan) => return scan,
                    }
                }
                pos = value + len as usize;
                continue;
            }
            if let Some(bad) = check_len(group, element, len, value, file_size) {
                return bad;
            }
            if sequence || len == UNDEFINED {
                open.push((len != UNDEFINED).then_some(value + len as usize));
                pos = value;
            } else {
                pos = value + len as usize;
            }
        }
        if open.len() > MAX_NESTING {
            return Scan::Bad(format!("sequences nested more than {MAX_NESTING} deep"));
        }
    }
}

/// Walks the items of encapsulated pixel data (offset table and fragments, raw bytes each) up
/// to the sequence delimiter; returns the offset after it.
fn scan_fragments(buf: &[u8], start: usize, file_size: u64, layout: Layout) -> Result<usize, Scan> {
    let mut pos = start;
    loop {
        if pos as u64 >= file_size {
            // No delimiter before the end: dicom-rs reports that; nothing more to allocate.
            return Ok(pos);
        }
        if pos + 8 > buf.len() {
            return Err(Scan::NeedMore(pos + 8));
        }
        let (group, element) = (layout.u16(&buf[pos..]), layout.u16(&buf[pos + 2..]));
        let len = layout.u32(&buf[pos + 4..]);
        match (group, element) {
            (0xFFFE, 0xE0DD) => return Ok(pos + 8),
            (0xFFFE, 0xE000) if len != UNDEFINED => {
                if let Some(bad) = check_len(group, element, len, pos + 8, file_size) {
                    return Err(bad);
                }
                pos += 8 + len as usize;
            }
            _ => {
                return Err(Scan::Bad(format!(
                    "encapsulated pixel data holds ({group:04X},{element:04X}) where a fragment item belongs"
                )));
            }
        }
    }
}

/// Header size, value length and whether the element is a sequence to descend into.
fn element_header(buf: &[u8], pos: usize, layout: Layout) -> Option<(usize, u32, bool)> {
    if !layout.explicit {
        let len = layout.u32(&buf[pos + 4..]);
        // Implicit VR does not say SQ: a defined-length value that starts with an item tag is one.
        let item = pos + 12 <= buf.len()
            && layout.u16(&buf[pos + 8..]) == 0xFFFE
            && layout.u16(&buf[pos + 10..]) == 0xE000;
        return Some((8, len, item));
    }
    let vr = &buf[pos + 4..pos + 6];
    // As in PS3.5 7.1.2 and dicom-rs: these VRs have a 16-bit length; all others, unknown
    // (corrupt) ones included, have two reserved bytes and a 32-bit length.
    let short = matches!(
        vr,
        b"AE"
            | b"AS"
            | b"AT"
            | b"CS"
            | b"DA"
            | b"DS"
            | b"DT"
            | b"FL"
            | b"FD"
            | b"IS"
            | b"LO"
            | b"LT"
            | b"PN"
            | b"SH"
            | b"SL"
            | b"SS"
            | b"ST"
            | b"TM"
            | b"UI"
            | b"UL"
            | b"US"
    );
    if !short {
        if pos + 12 > buf.len() {
            return None;
        }
        Some((12, layout.u32(&buf[pos + 8..]), vr == b"SQ"))
    } else {
        Some((8, u32::from(layout.u16(&buf[pos + 6..])), false))
    }
}

fn check_len(group: u16, element: u16, len: u32, value: usize, file_size: u64) -> Option<Scan> {
    let left = file_size.saturating_sub(value as u64);
    (len != UNDEFINED && u64::from(len) > left).then(|| {
        Scan::Bad(format!(
            "the file is cut short or corrupt: element ({group:04X},{element:04X}) announces {len} bytes, but only {left} remain"
        ))
    })
}
