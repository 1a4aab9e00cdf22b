//! The header pass: which files of a folder are DICOM images, and each image's header
//! (series, pixel format, planes, spacing) read up to the pixel data.

use std::{
    panic::{AssertUnwindSafe, catch_unwind},
    path::{Path, PathBuf},
};

use dicom_core::{
    Tag,
    value::{PrimitiveValue, Value},
};
use dicom_dictionary_std::tags;
use dicom_object::{DefaultDicomObject, InMemDicomObject};
use glam::DVec3;

use super::lenient::open_dicom;
use voyage_core::{Error, Result, check_dims};
// ---------------------------------------------------------------------------------------------
// Header pass
// ---------------------------------------------------------------------------------------------

/// The SOP class of a DICOMDIR (an index of a disc, not an image).
const MEDIA_STORAGE_DIRECTORY: &str = "1.2.840.10008.1.3.10";

/// What the header pass learned about one file.
pub(super) enum Probe {
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
pub(super) struct Header {
    pub(super) path: PathBuf,
    pub(super) series_uid: String,
    pub(super) series_description: Option<String>,
    pub(super) modality: Option<String>,
    pub(super) ts_uid: String,
    pub(super) rows: usize,
    pub(super) cols: usize,
    pub(super) frames: usize,
    pub(super) pixel: PixelFormat,
    /// One entry per frame.
    pub(super) planes: Vec<Plane>,
    /// SpacingBetweenSlices, else SliceThickness (for single slices and multi-frame files
    /// without per-frame positions).
    pub(super) slice_step: Option<f64>,
    pub(super) gantry_tilt_deg: Option<f64>,
    /// LossyImageCompression is "01": the pixels went through lossy compression at some point.
    pub(super) lossy: bool,
    /// PatientPosition (0018,5100) as written ("HFS", "FFP", ...).
    pub(super) position: Option<String>,
    pub(super) series_number: Option<i64>,
    /// YYYY-MM-DD ([`exam_date`]).
    pub(super) exam_date: Option<String>,
}

/// How stored pixel values are laid out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct PixelFormat {
    pub(super) bits_allocated: u16,
    pub(super) bits_stored: u16,
    pub(super) high_bit: u16,
    pub(super) signed: bool,
}

impl PixelFormat {
    pub(super) fn bytes_per_sample(&self) -> usize {
        usize::from(self.bits_allocated / 8)
    }
}

/// Stored value → HU: `hu = stored × slope + intercept`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Rescale {
    pub(super) slope: f64,
    pub(super) intercept: f64,
}

/// Where one frame lies in the patient, as its header says.
#[derive(Clone, Debug)]
pub(super) struct Plane {
    pub(super) position: Option<DVec3>,
    /// Row cosine (direction of increasing column index, i) and column cosine (increasing row
    /// index, j).
    pub(super) orientation: Option<[DVec3; 2]>,
    /// [along i (between columns), along j (between rows)] in mm. DICOM PixelSpacing lists them
    /// the other way round: row spacing first.
    pub(super) spacing: Option<[f64; 2]>,
    pub(super) rescale: Rescale,
}

pub(super) fn list_files(dir: &Path) -> Result<Vec<PathBuf>> {
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
pub(super) fn probe_file(path: &Path) -> Result<Probe> {
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
pub(super) fn has_dicm_marker(path: &Path) -> Result<bool> {
    let mut head = [0u8; 132];
    let n = crate::read_prefix(path, &mut head)?;
    Ok((n >= 132 && &head[128..132] == b"DICM") || (n >= 4 && &head[0..4] == b"DICM"))
}

/// Runs `f`, converting a panic (a bug or an unchecked case in a decoder) into an error that
/// names the file, so that no input can crash the program.
pub(super) fn guarded<T>(path: &Path, what: &str, f: impl FnOnce() -> Result<T>) -> Result<T> {
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

pub(super) fn parse_header(
    path: &Path,
    obj: &DefaultDicomObject,
) -> std::result::Result<Probe, String> {
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
pub(super) fn parse_pixel_format(
    obj: &InMemDicomObject,
) -> std::result::Result<PixelFormat, String> {
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
pub(super) fn parse_planes(
    obj: &InMemDicomObject,
    frames: usize,
) -> std::result::Result<Vec<Plane>, String> {
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
pub(super) fn grouped_floats(
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

pub(super) fn vec3(v: &[f64], name: &str) -> std::result::Result<DVec3, String> {
    match v {
        [x, y, z] => Ok(DVec3::new(*x, *y, *z)),
        _ => Err(format!("{name} has {} values, expected 3", v.len())),
    }
}

/// Checks that ImageOrientationPatient holds two orthogonal unit vectors, and makes them
/// exactly orthonormal (values are written with a few decimals).
pub(super) fn orientation(v: &[f64]) -> std::result::Result<[DVec3; 2], String> {
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

pub(super) fn pixel_spacing(v: &[f64]) -> std::result::Result<[f64; 2], String> {
    match v {
        [between_rows, between_cols] if *between_rows > 0.0 && *between_cols > 0.0 => {
            Ok([*between_cols, *between_rows])
        }
        _ => Err(format!("PixelSpacing {v:?} is not two positive numbers")),
    }
}

pub(super) fn text(obj: &InMemDicomObject, tag: Tag) -> Option<String> {
    let s = obj.get(tag)?.to_str().ok()?;
    let s = s.trim_matches(|c: char| c.is_whitespace() || c == '\0');
    (!s.is_empty()).then(|| s.to_string())
}

/// The exam's date, YYYY-MM-DD: StudyDate, else SeriesDate, else AcquisitionDate (DA,
/// "YYYYMMDD"; the old "YYYY.MM.DD" too). A value that is not a date is passed over.
pub(super) fn exam_date(obj: &InMemDicomObject) -> Option<String> {
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
pub(super) fn uint(
    obj: &InMemDicomObject,
    tag: Tag,
    name: &str,
) -> std::result::Result<Option<u64>, String> {
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
pub(super) fn is_empty(elem: &dicom_object::mem::InMemElement) -> bool {
    match elem.value() {
        Value::Primitive(PrimitiveValue::Empty) => true,
        Value::Primitive(p) => p
            .to_str()
            .trim_matches(|c: char| c.is_whitespace() || c == '\0')
            .is_empty(),
        _ => false,
    }
}

pub(super) fn float(
    obj: &InMemDicomObject,
    tag: Tag,
    name: &str,
) -> std::result::Result<Option<f64>, String> {
    Ok(floats(obj, tag, name)?.and_then(|v| v.first().copied()))
}

/// A decimal attribute with any number of values: `None` when absent or empty, an error when
/// unreadable or not finite.
pub(super) fn floats(
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

pub(super) fn no_images_error(
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
pub(super) fn gzipped_files(non_dicom: &[PathBuf]) -> Option<String> {
    let gz: Vec<String> = non_dicom
        .iter()
        .filter(|p| {
            let mut head = [0u8; 2];
            matches!(crate::read_prefix(p, &mut head), Ok(2)) && head == [0x1f, 0x8b]
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

pub(super) fn skipped_notes(non_dicom: &[PathBuf], non_image: &[(PathBuf, String)]) -> Vec<String> {
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

pub(super) fn file_name(p: &Path) -> String {
    p.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| p.display().to_string())
}
