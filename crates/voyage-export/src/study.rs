//! The files `voyage prep` writes from a [`Study`].

use std::path::{Path, PathBuf};

use glam::DVec3;
use serde_json::json;

use super::{MarkupsPoint, write_markups_curve, write_ply, write_stl};
use voyage_core::{Result, Study};
use voyage_io::{nifti, write_atomic};

/// Which optional exports [`write_study`] adds.
#[derive(Clone, Copy, Debug, Default)]
pub struct StudyExports {
    /// `surface.stl` beside the PLY: STL repeats each vertex per triangle, so it is about
    /// twice the PLY's size (146 MB for a real exam), and only some tools need it.
    pub stl: bool,
}

/// Every file [`write_study`] may write. Those a run does not write are removed from the
/// folder it writes into: a plain exam's exports never stand beside an earlier tagged one's
/// `cleansed.nii.gz`.
pub const STUDY_FILES: [&str; 8] = [
    "lumen.nii.gz",
    "ds.nii.gz",
    "cleansed.nii.gz",
    "centerline.json",
    "centerline.mrk.json",
    "surface.ply",
    "surface.stl",
    "cells.json",
];

/// The staging folders' prefix (a process id follows).
const STAGING: &str = ".voyage-prep-";

/// Writes every export of a study into `dir`; returns the paths written.
///
/// All or nothing: the files are written into a staging folder inside `dir` and moved into
/// place only when every one of them is complete, so a failure (a full disk, a folder in the
/// way) leaves `dir` as it was, never a new lumen beside an old surface. A `dir` this call
/// created is removed again. Of [`STUDY_FILES`], those this study has none of are removed
/// once the others are in place, and so are the staging folders of runs that were stopped.
pub fn write_study(dir: &Path, study: &Study, extra: StudyExports) -> Result<Vec<PathBuf>> {
    let created = !dir.exists();
    std::fs::create_dir_all(dir).map_err(|e| voyage_core::Error::io(dir, e))?;
    remove_stale_staging(dir);
    let staging = dir.join(format!("{STAGING}{}", std::process::id()));
    let result = std::fs::create_dir(&staging)
        .map_err(|e| voyage_core::Error::io(&staging, e))
        .and_then(|()| write_files(&staging, study, extra))
        .and_then(|names| move_into(dir, &staging, &names));
    let _ = std::fs::remove_dir_all(&staging);
    if result.is_err() && created {
        let _ = std::fs::remove_dir(dir);
    }
    result
}

/// Moves the staged files into `dir`, after checking that none would land on a folder.
fn move_into(dir: &Path, staging: &Path, names: &[&str]) -> Result<Vec<PathBuf>> {
    let paths: Vec<PathBuf> = names.iter().map(|n| dir.join(n)).collect();
    if let Some(p) = paths.iter().find(|p| p.is_dir()) {
        return Err(voyage_core::Error::format(
            p,
            "a folder is in the way of this export",
        ));
    }
    for (name, p) in names.iter().zip(&paths) {
        std::fs::rename(staging.join(name), p).map_err(|e| voyage_core::Error::io(p, e))?;
    }
    for stale in STUDY_FILES.iter().filter(|n| !names.contains(n)) {
        let p = dir.join(stale);
        if p.is_file() {
            std::fs::remove_file(&p).map_err(|e| voyage_core::Error::io(&p, e))?;
        }
    }
    Ok(paths)
}

/// Removes the staging folders in `dir` of runs no longer running (a `prep` stopped while it
/// wrote leaves one behind).
fn remove_stale_staging(dir: &Path) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name();
        let Some(pid) = name
            .to_str()
            .and_then(|n| n.strip_prefix(STAGING))
            .and_then(|p| p.parse::<u32>().ok())
        else {
            continue;
        };
        if pid != std::process::id() && !process_runs(pid) && e.path().is_dir() {
            let _ = std::fs::remove_dir_all(e.path());
        }
    }
}

/// Whether process `pid` runs (on Linux; elsewhere every process is taken to run, and a
/// stale staging folder stays).
fn process_runs(pid: u32) -> bool {
    if cfg!(target_os = "linux") {
        Path::new("/proc").join(pid.to_string()).exists()
    } else {
        true
    }
}

/// Checks, before any work, that the exports can be written into `dir`: an existing folder
/// that takes a file, or a folder that can be made (it is not made now). A file in the way or
/// a read-only folder is found here, not after the preprocessing.
pub fn check_out_dir(dir: &Path) -> Result<()> {
    let mut existing = dir;
    while !existing.exists() {
        match existing.parent() {
            Some(p) if !p.as_os_str().is_empty() => existing = p,
            _ => {
                existing = Path::new(".");
                break;
            }
        }
    }
    if !existing.is_dir() {
        return Err(voyage_core::Error::format(
            existing,
            "is not a folder: the exports cannot be written there",
        ));
    }
    let probe = existing.join(format!(".voyage-probe-{}", std::process::id()));
    std::fs::write(&probe, b"")
        .map_err(|e| voyage_core::Error::io(existing, e))
        .map(|()| {
            let _ = std::fs::remove_file(&probe);
        })
}

/// The lumen, Ds and the cleansed CT, on the input's grid (the study is made in its own
/// storage: [`voyage_core::Storage`]). Ds is compressed beside the other two: gzip is most of
/// the exports' time (on `ctc/prone-tagged` 2.6 s of a 10 s `voyage prep`). The lumen and the
/// cleansed CT go one after the other, so that their copies on the input's grid (when the
/// storage is not the input's) are not held together.
fn write_volumes(study: &Study, put: &mut impl FnMut(&'static str) -> PathBuf) -> Result<()> {
    let lumen = put("lumen.nii.gz");
    let ds = put("ds.nii.gz");
    let cleansed = (!study.cleansing.is_empty()).then(|| put("cleansed.nii.gz"));
    let (a, b) = rayon::join(
        || {
            write_lumen(study, &lumen)?;
            cleansed.map_or(Ok(()), |path| write_cleansed(study, &path))
        },
        || write_ds(study, &ds),
    );
    a.and(b)
}

fn write_lumen(study: &Study, path: &Path) -> Result<()> {
    let st = &study.storage;
    if st.is_identity() {
        nifti::save(path, &study.segmentation.lumen)
    } else {
        nifti::save(path, &st.to_input(&study.segmentation.lumen)?)
    }
}

fn write_ds(study: &Study, path: &Path) -> Result<()> {
    let st = &study.storage;
    let g = st.input_geometry();
    if st.is_identity() {
        nifti::save_slices(path, g, |k, out: &mut [f32]| study.ds.fill_slice(k, out))
    } else {
        nifti::save_slices(path, g, |k, out: &mut [f32]| {
            st.fill_input_slice(k, out, |v| study.ds.get(v))
        })
    }
}

fn write_cleansed(study: &Study, path: &Path) -> Result<()> {
    let st = &study.storage;
    let g = st.input_geometry();
    if st.is_identity() {
        return nifti::save_slices(path, g, |k, out: &mut [i16]| {
            study.cleansing.fill_slice(&study.ct, k, out)
        });
    }
    let c = study.cleansed_ct();
    let cg = c.geometry();
    nifti::save_slices(path, g, |k, out: &mut [i16]| {
        st.fill_input_slice(k, out, |v| c.data()[cg.index(v[0], v[1], v[2])])
    })
}

/// Writes the exports into `dir`; returns their file names.
fn write_files(dir: &Path, study: &Study, extra: StudyExports) -> Result<Vec<&'static str>> {
    let g = study.ct.geometry();
    let mut out = Vec::new();
    let mut put = |name: &'static str| {
        out.push(name);
        dir.join(name)
    };
    write_volumes(study, &mut put)?;
    let cl = &study.centerline;
    let lps: Vec<[f64; 3]> = cl
        .points_mm
        .iter()
        .map(|p| g.local_to_patient(DVec3::from_array(*p)).to_array())
        .collect();
    let cl_json = json!({
        "frame": "points_mm: study-local mm (x = i·sx, y = j·sy, z = k·sz with the scan turned so that i, j, k run to the patient's left, back and head); points_lps_mm: DICOM patient LPS",
        "length_mm": cl.length_mm,
        "source_mm": study.source_mm().to_array(),
        "target_mm": study.target_mm().to_array(),
        "points_mm": cl.points_mm,
        "points_lps_mm": lps,
        "arc_mm": cl.arc_mm,
        "radius_mm": cl.radius_mm,
        // Stretches (arc mm from the source, start and end) through bridged gaps: collapsed
        // or fluid-filled bowel, no air.
        "collapsed_arc_mm": study.collapsed_spans(),
        // From the source, a canal too narrow to fly (the anal canal round a catheter): the
        // flights start and end above it. 0 when none.
        "canal_mm": cl.canal_mm,
    });
    write_json(&put("centerline.json"), &cl_json)?;
    let points: Vec<MarkupsPoint> = lps
        .iter()
        .step_by(5)
        .chain(lps.last())
        .enumerate()
        .map(|(i, p)| MarkupsPoint {
            label: format!("CL-{}", i + 1),
            position_lps: *p,
            description: String::new(),
        })
        .collect();
    write_markups_curve(&put("centerline.mrk.json"), "Centerline", &points)?;
    write_ply(&put("surface.ply"), &study.surface.mesh, g)?;
    if extra.stl {
        write_stl(&put("surface.stl"), &study.surface.mesh, g)?;
    }
    let cells: Vec<_> = study
        .cells
        .cells
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let portal = |p: Option<usize>| {
                p.map(|p| {
                    let portal = &study.cells.portals[p];
                    json!({
                        "index": p,
                        "centre_mm": portal.centre_mm,
                        "normal": portal.normal,
                        "polygon_mm": portal.polygon_mm,
                        "polygon_lps_mm": portal.polygon_mm.iter().map(|q| g.local_to_patient(DVec3::from_array(*q)).to_array()).collect::<Vec<_>>(),
                        "half_thickness_mm": portal.half_thickness_mm,
                    })
                })
            };
            json!({
                "cell": i,
                "triangles": c.triangles.len(),
                "voxels": c.voxels,
                "centerline_span": [c.centerline_span.0, c.centerline_span.1],
                "arc_mm": [cl.arc_mm[c.centerline_span.0], cl.arc_mm[c.centerline_span.1]],
                "portal_back": portal(c.portal_back),
                "portal_front": portal(c.portal_front),
            })
        })
        .collect();
    write_json(
        &put("cells.json"),
        &json!({ "frame": "study-local mm (as in centerline.json), with LPS copies", "cells": cells }),
    )?;
    Ok(out)
}

/// A JSON value, pretty-printed, written atomically.
pub(crate) fn write_json(path: &Path, v: &serde_json::Value) -> Result<()> {
    let text = serde_json::to_string_pretty(v).expect("plain data") + "\n";
    write_atomic(path, |w| w.write_all(text.as_bytes()))
}
