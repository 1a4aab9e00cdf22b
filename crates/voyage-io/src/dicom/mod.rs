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
//! dicom-rs allocates for it, image sizes go through [`voyage_core::check_dims`], and any panic inside the
//! DICOM libraries is caught and reported as an error naming the file.
//!
//! Patient name and ID are never read.

use std::path::Path;

use rayon::prelude::*;

use self::header::{
    Header, Probe, gzipped_files, list_files, no_images_error, probe_file, skipped_notes,
};
use self::pixels::load_series;
use self::series::{choose_series, rank, summary};
pub use self::stack::OUTSIDE_HU;
use super::{LoadOptions, Loaded, SeriesSummary};
use voyage_core::{Error, PatientPosition, Result};

mod header;
mod lenient;
mod pixels;
mod series;
mod stack;

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

/// A series of fewer slices is no position of an exam (a localizer, a few slices of a
/// region): a colon spans 40 slices even at 5 mm.
pub const EXAM_MIN_SLICES: usize = 40;

/// The series of an exam scanned in several positions (supine and prone ...): for each
/// patient position the CT series hold, by the way gravity pulls (head or feet first alike),
/// the one a folder of that position alone would load (CT first, the most slices, ties by
/// UID), as (position, SeriesInstanceUID): supine first, then prone, then the decubitus
/// ones. Only CT series of [`EXAM_MIN_SLICES`] slices or more that say their position count
/// (a localizer or a secondary capture beside the exam is not a position). Only headers are
/// read.
pub fn positions_in(path: &Path) -> Result<Vec<(PatientPosition, String)>> {
    let files = list_files(path)?;
    let headers: Vec<Result<Probe>> = files.par_iter().map(|f| probe_file(f)).collect();
    let mut by_series: Vec<(String, Vec<Header>)> = Vec::new();
    for probe in headers {
        if let Probe::Image(h) = probe? {
            match by_series.iter_mut().find(|(uid, _)| *uid == h.series_uid) {
                Some((_, hs)) => hs.push(*h),
                None => by_series.push((h.series_uid.clone(), vec![*h])),
            }
        }
    }
    let mut best: Vec<(PatientPosition, SeriesSummary)> = Vec::new();
    for (uid, hs) in &by_series {
        let Some(position) = hs
            .iter()
            .find_map(|h| h.position.as_deref().and_then(PatientPosition::parse))
        else {
            continue;
        };
        let s = summary(uid, hs);
        if s.modality.as_deref() != Some("CT") || s.slices < EXAM_MIN_SLICES {
            continue;
        }
        let same_way = |p: &PatientPosition| p.gravity_lps() == position.gravity_lps();
        match best.iter_mut().find(|(p, _)| same_way(p)) {
            Some(b)
                if (rank(&s), std::cmp::Reverse(&s.uid))
                    > (rank(&b.1), std::cmp::Reverse(&b.1.uid)) =>
            {
                *b = (position, s)
            }
            Some(_) => {}
            None => best.push((position, s)),
        }
    }
    let order = |p: &PatientPosition| match p.gravity_lps().to_array() {
        [_, y, _] if y > 0.5 => 0,
        [_, y, _] if y < -0.5 => 1,
        [x, _, _] if x < 0.0 => 2,
        _ => 3,
    };
    best.sort_by_key(|(p, _)| order(p));
    Ok(best.into_iter().map(|(p, s)| (p, s.uid)).collect())
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
