//! The `voyage` binary as a user meets it: exit codes, one-line errors naming the file,
//! no patient identity in any output, and the phantom → file → info round trip.

use std::{
    path::{Path, PathBuf},
    process::{Command, Output},
};

fn voyage(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_voyage"))
        .args(args)
        .output()
        .expect("run voyage")
}

use voyage_phantom::fixtures::shared_data;

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("voyage-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// The small colon phantom written into `dir` as `ct.nii` and as a DICOM series, `series/`
/// (returned).
fn small_series(dir: &Path) -> PathBuf {
    let (ct, series) = (dir.join("ct.nii"), dir.join("series"));
    let made = voyage(&[
        "phantom",
        "colon",
        "--small",
        "--out",
        ct.to_str().unwrap(),
        "--dicom",
        series.to_str().unwrap(),
    ]);
    assert!(made.status.success(), "{}", text(&made));
    series
}

/// Identity strings present in the shared test files' headers; none may ever be printed.
const IDENTITIES: [&str; 6] = [
    "MISTER",
    "2178309",
    "CompressedSamples",
    "1CT1",
    "QMNx85rKkkg",
    "REMOVED",
];

fn assert_private(o: &Output) {
    let t = text(o);
    for id in IDENTITIES {
        assert!(!t.contains(id), "patient identity {id:?} printed:\n{t}");
    }
}

#[test]
fn info_on_each_dicom_folder() {
    let Some(data) = shared_data() else { return };
    let chest = voyage(&[
        "info",
        "--json",
        data.join("dicom/chest-reversed").to_str().unwrap(),
    ]);
    assert!(chest.status.success(), "{}", text(&chest));
    let j: serde_json::Value = serde_json::from_slice(&chest.stdout).unwrap();
    assert_eq!(j["dims"], serde_json::json!([512, 512, 40]));
    assert_eq!(
        j["orientation"], "LPS",
        "k must run toward superior after sorting"
    );
    assert_eq!(j["modality"], "CT");
    let abd = voyage(&["info", data.join("dicom/abdomen-j2k").to_str().unwrap()]);
    assert!(abd.status.success(), "{}", text(&abd));
    assert!(text(&abd).contains("512 × 512 × 20"));
    let tilt = voyage(&[
        "info",
        data.join("dicom/head-gantry-tilt").to_str().unwrap(),
    ]);
    assert!(!tilt.status.success());
    let err = String::from_utf8_lossy(&tilt.stderr);
    assert!(
        err.contains("tilt") && err.contains("head-gantry-tilt"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "one-line error: {err}");
    for o in [&chest, &abd, &tilt] {
        assert_private(o);
    }
}

#[test]
fn every_transfer_syntax_file_reports_or_fails_cleanly() {
    let Some(data) = shared_data() else { return };
    for e in std::fs::read_dir(data.join("dicom/transfer-syntaxes")).unwrap() {
        let p = e.unwrap().path();
        let o = voyage(&["info", "--json", p.to_str().unwrap()]);
        assert_private(&o);
        if o.status.success() {
            let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
            assert_eq!(j["dims"][0], 512, "{}", p.display());
        } else {
            let err = String::from_utf8_lossy(&o.stderr);
            let name = p.file_name().unwrap().to_string_lossy();
            assert!(
                err.contains(name.as_ref()),
                "error does not name the file: {err}"
            );
            assert_eq!(err.trim().lines().count(), 1, "{err}");
        }
    }
}

#[test]
fn broken_inputs_fail_with_one_line_naming_the_file() {
    let dir = scratch("broken");
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let texts = dir.join("texts");
    std::fs::create_dir_all(&texts).unwrap();
    std::fs::write(texts.join("README"), "not a scan").unwrap();
    std::fs::write(texts.join("notes.txt"), "nor this").unwrap();
    let huge = dir.join("huge.nii");
    let mut hdr = vec![0u8; 352];
    hdr[0..4].copy_from_slice(&348i32.to_le_bytes());
    for (i, d) in [3i16, 32767, 32767, 32767, 1, 1, 1, 1].iter().enumerate() {
        hdr[40 + 2 * i..42 + 2 * i].copy_from_slice(&d.to_le_bytes());
    }
    hdr[70..72].copy_from_slice(&4i16.to_le_bytes());
    hdr[72..74].copy_from_slice(&16i16.to_le_bytes());
    for i in 0..4 {
        hdr[76 + 4 * i..80 + 4 * i].copy_from_slice(&1f32.to_le_bytes());
    }
    hdr[108..112].copy_from_slice(&352f32.to_le_bytes());
    hdr[344..348].copy_from_slice(b"n+1\0");
    std::fs::write(&huge, &hdr).unwrap();
    let mut cases: Vec<PathBuf> = vec![empty, texts, huge, dir.join("missing.nii.gz")];
    if let Some(data) = shared_data() {
        for e in std::fs::read_dir(data.join("dicom/broken")).unwrap() {
            cases.push(e.unwrap().path());
        }
        let real = std::fs::read(data.join("ct/abdomen-3mm.nii.gz")).unwrap();
        let cut = dir.join("cut.nii.gz");
        std::fs::write(&cut, &real[..real.len() / 2]).unwrap();
        cases.push(cut);
    }
    for p in cases {
        let o = voyage(&["info", p.to_str().unwrap()]);
        assert!(!o.status.success(), "{} loaded", p.display());
        let err = String::from_utf8_lossy(&o.stderr);
        let name = p.file_name().unwrap().to_string_lossy();
        assert!(
            err.starts_with("error: ") && err.contains(name.as_ref()),
            "{}: {err}",
            p.display()
        );
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(
            err.matches("os error").count() <= 1,
            "the reason twice: {err}"
        );
        assert_private(&o);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn phantom_files_round_trip_through_info() {
    let dir = scratch("phantom");
    let ct = dir.join("colon.nii.gz");
    let truth = dir.join("colon.json");
    let series = dir.join("series");
    let o = voyage(&[
        "phantom",
        "colon",
        "--small",
        "--seed",
        "3",
        "--out",
        ct.to_str().unwrap(),
        "--truth",
        truth.to_str().unwrap(),
        "--dicom",
        series.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let t: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&truth).unwrap()).unwrap();
    assert!(
        dir.join(t["lumen_mask"].as_str().unwrap()).is_file(),
        "lumen mask beside the truth"
    );
    let infos = [&ct, &series].map(|p| voyage(&["info", "--json", p.to_str().unwrap()]).stdout);
    // Strict JSON readers refuse a repeated key (`format` was printed twice).
    for out in &infos {
        let text = String::from_utf8_lossy(out);
        let keys: Vec<&str> = text
            .lines()
            .filter(|l| l.starts_with("  \"") && l.contains("\":"))
            .map(|l| l.trim().split('"').nth(1).unwrap())
            .collect();
        let mut unique = keys.clone();
        unique.sort_unstable();
        unique.dedup();
        assert_eq!(
            unique.len(),
            keys.len(),
            "a key repeats in info --json: {keys:?}"
        );
        assert!(keys.contains(&"format"));
    }
    let [a, b]: [serde_json::Value; 2] = infos.map(|o| serde_json::from_slice(&o).unwrap());
    for key in ["dims", "orientation", "hu_min", "hu_max"] {
        assert_eq!(a[key], b[key], "{key} differs between NIfTI and DICOM");
    }
    for axis in 0..3 {
        let (x, y) = (
            a["spacing_mm"][axis].as_f64().unwrap(),
            b["spacing_mm"][axis].as_f64().unwrap(),
        );
        assert!((x - y).abs() < 1e-4, "spacing {x} vs {y}");
    }
    assert_eq!(b["modality"], "CT");
    assert_eq!(a["dims"], t["dims"]);
    // SeriesDescription is free text (it can hold a name): shown only when asked for.
    let described = |args: &[&str]| {
        let mut all = vec!["info", series.to_str().unwrap()];
        all.extend(args);
        let o = voyage(&all);
        assert!(o.status.success(), "{}", text(&o));
        String::from_utf8_lossy(&o.stdout).contains("voyage volume")
    };
    assert!(!described(&[]) && !described(&["--json"]));
    assert!(described(&["--show-descriptions"]));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_arguments_are_refused() {
    let o = voyage(&[
        "phantom",
        "colon",
        "--out",
        "/nonexistent-dir/x.nii.gz",
        "--small",
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("/nonexistent-dir/x.nii.gz"));
    let o = voyage(&["phantom", "colon", "--out", "x.unknown", "--small"]);
    assert!(!o.status.success());
}

/// A window script with a step the window does not know is refused with the script's name
/// before any window opens (no display is needed to say so): an unattended run would
/// otherwise wait with nothing to do.
#[test]
fn a_script_with_an_unknown_step_is_refused_before_the_window_opens() {
    let dir = scratch("bad-script");
    for (name, steps) in [
        ("direction.json", r#"[{"direction": "sideways"}]"#),
        ("step.json", r#"[{"fly_to_moon": 1}]"#),
    ] {
        let script = dir.join(name);
        std::fs::write(&script, steps).unwrap();
        let o = Command::new(env!("CARGO_BIN_EXE_voyage"))
            .args(["demo", "--small", "--script", script.to_str().unwrap()])
            .env_remove("DISPLAY")
            .env_remove("WAYLAND_DISPLAY")
            .output()
            .expect("run voyage");
        assert!(!o.status.success(), "{}", text(&o));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(name) && err.contains("script"), "{err}");
        assert!(!err.contains("display"), "{err}");
    }
}

/// A CT slice whose RLE segments decode short makes dicom-rs's decoder panic (found by the
/// fuzzer). voyage turns that into its usual one-line error, with no panic report or backtrace.
#[test]
fn a_panicking_decoder_still_gives_one_line() {
    use dicom_core::{
        DataElement, VR,
        value::{PixelFragmentSequence, PrimitiveValue},
    };
    use dicom_dictionary_std::tags;
    let dir = scratch("rle");
    let series = small_series(&dir);
    let first = std::fs::read_dir(&series)
        .unwrap()
        .map(|e| e.unwrap().path())
        .min()
        .unwrap();
    let mut obj = dicom_object::open_file(&first).unwrap();
    obj.meta_mut().transfer_syntax = "1.2.840.10008.1.2.5".to_string();
    let mut frame = vec![0u8; 64];
    frame[0..4].copy_from_slice(&2u32.to_le_bytes());
    frame[4..8].copy_from_slice(&64u32.to_le_bytes());
    frame[8..12].copy_from_slice(&66u32.to_le_bytes());
    frame.extend_from_slice(&[0x00, 0x01, 0x00, 0x02]);
    obj.put(DataElement::new(
        tags::PIXEL_DATA,
        VR::OB,
        PixelFragmentSequence::new(Vec::<u32>::new(), vec![frame]),
    ));
    obj.put(DataElement::new(
        tags::ROWS,
        VR::US,
        PrimitiveValue::from(4u16),
    ));
    obj.put(DataElement::new(
        tags::COLUMNS,
        VR::US,
        PrimitiveValue::from(4u16),
    ));
    let bad = dir.join("short-rle.dcm");
    obj.write_to_file(&bad).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_voyage"))
        .args(["info", bad.to_str().unwrap()])
        .env("RUST_BACKTRACE", "1")
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(
        err.starts_with("error: ") && err.contains("short-rle.dcm") && !err.contains("panicked"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `voyage phantom colon --small ARGS --out OUT`, which must succeed.
fn small_colon(out: &Path, args: &[&str]) {
    let made = voyage(
        &[
            &[
                "phantom",
                "colon",
                "--small",
                "--out",
                out.to_str().unwrap(),
            ],
            args,
        ]
        .concat(),
    );
    assert!(made.status.success(), "{}", text(&made));
}

#[test]
fn prep_writes_its_exports_and_reports_json() {
    let dir = scratch("prep");
    let ct = dir.join("colon.nii.gz");
    let truth = dir.join("colon.json");
    small_colon(&ct, &["--truth", truth.to_str().unwrap()]);
    let out = dir.join("prep");
    let o = voyage(&[
        "prep",
        ct.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    for key in [
        "lumen_voxels",
        "components",
        "source_mm",
        "target_mm",
        "centerline_length_mm",
        "cells",
        "triangles",
        "timings_ms",
        "peak_rss_mb",
        "position",
        "position_source",
        "gravity_lps",
        "segments",
        "gaps",
        "warnings",
    ] {
        assert!(!j[key].is_null(), "{key} missing from {j}");
    }
    // No fluid, no DICOM header: supine is assumed, and said, in the JSON and on stderr.
    assert_eq!(j["position"], "HFS");
    assert_eq!(j["position_source"], "assumed");
    assert_eq!(j["gravity_lps"], serde_json::json!([0.0, 1.0, 0.0]));
    assert!(
        j["warnings"][0]
            .as_str()
            .unwrap()
            .contains("supine assumed"),
        "{j}"
    );
    assert!(
        String::from_utf8_lossy(&o.stderr)
            .lines()
            .any(|l| l.starts_with("warning:") && l.contains("supine assumed"))
    );
    assert_eq!(j["segments"][0]["kept"], true);
    assert_eq!(j["segments"][0]["order"], 0);
    assert_eq!(j["gaps"], serde_json::json!([]));
    // --position overrides: the view's up and the fluid side follow it.
    let prone = voyage(&[
        "prep",
        ct.to_str().unwrap(),
        "--out",
        dir.join("prone").to_str().unwrap(),
        "--json",
        "--position",
        "hfp",
        "--stl",
    ]);
    assert!(prone.status.success(), "{}", text(&prone));
    // STL only when asked: it is larger than the PLY (twice, here).
    let stl = dir
        .join("prone/surface.stl")
        .metadata()
        .map(|m| m.len())
        .unwrap_or(0);
    let ply = dir.join("prone/surface.ply").metadata().unwrap().len();
    assert!(stl > ply, "--stl wrote {stl} bytes beside a {ply}-byte PLY");
    let p: serde_json::Value = serde_json::from_slice(&prone.stdout).unwrap();
    assert_eq!(
        (p["position"].as_str(), p["position_source"].as_str()),
        (Some("HFP"), Some("given"))
    );
    assert_eq!(p["gravity_lps"], serde_json::json!([0.0, -1.0, 0.0]));
    assert!(
        p["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .all(|w| !w.as_str().unwrap().contains("assumed")),
        "{p}"
    );
    for key in [
        "load",
        "segment",
        "ds",
        "dt",
        "centerline",
        "cells",
        "surface",
        "total_after_load",
    ] {
        assert!(
            j["timings_ms"][key].as_f64().is_some(),
            "timings_ms.{key} missing"
        );
    }
    let t: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&truth).unwrap()).unwrap();
    let (ours, truth_len) = (
        j["centerline_length_mm"].as_f64().unwrap(),
        t["centerline_length_mm"].as_f64().unwrap(),
    );
    assert!(
        (ours - truth_len).abs() < 0.1 * truth_len,
        "centerline {ours} mm vs truth {truth_len} mm"
    );
    for f in [
        "lumen.nii.gz",
        "ds.nii.gz",
        "centerline.json",
        "centerline.mrk.json",
        "surface.ply",
        "cells.json",
    ] {
        assert!(
            out.join(f).metadata().map(|m| m.len() > 0).unwrap_or(false),
            "{f} not written"
        );
    }
    assert!(
        !out.join("surface.stl").exists(),
        "surface.stl written unasked"
    );
    assert!(
        !out.join("cleansed.nii.gz").exists() && j["cleanse"].is_null(),
        "no tagged fluid, nothing to cleanse"
    );
    let mrk: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("centerline.mrk.json")).unwrap())
            .unwrap();
    assert_eq!(mrk["markups"][0]["type"], "Curve");
    assert_eq!(mrk["markups"][0]["coordinateSystem"], "LPS");
    // A seed in soft tissue is refused on one line.
    let bad = voyage(&[
        "prep",
        ct.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--coords",
        "local",
        "--seed",
        "1,1,1",
    ]);
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        err.contains("seed") && err.trim().lines().count() == 1,
        "{err}"
    );
    // Negative coordinates are coordinates, not options; the error gives the point in LPS.
    let below = voyage(&[
        "prep",
        ct.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--seed",
        "-5000,1,1",
    ]);
    let err = String::from_utf8_lossy(&below.stderr);
    assert!(
        !below.status.success()
            && err.contains("the seed at LPS (-5000.0, 1.0, 1.0) mm")
            && err.contains("outside the volume"),
        "{err}"
    );
    // All or nothing: a folder where an export goes fails the whole write, naming it, and the
    // files already there stay as they were.
    let blocked = dir.join("blocked");
    std::fs::create_dir_all(blocked.join("surface.ply")).unwrap();
    std::fs::write(blocked.join("lumen.nii.gz"), b"old").unwrap();
    let o = voyage(&[
        "prep",
        ct.to_str().unwrap(),
        "--out",
        blocked.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    let errors: Vec<&str> = err.lines().filter(|l| !l.starts_with("warning:")).collect();
    assert!(
        !o.status.success() && err.contains("surface.ply") && errors.len() == 1,
        "{err}"
    );
    assert_eq!(std::fs::read(blocked.join("lumen.nii.gz")).unwrap(), b"old");
    let left: Vec<_> = std::fs::read_dir(&blocked)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left.len(), 2, "left behind: {left:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A tagged exam is cleansed by default: `cleansed.nii.gz` (the input's grid, i16 HU, the
/// colon's fluid made air), the JSON's `cleanse` and `surface_roughness`; `--no-cleanse`
/// keeps the fluid and writes no cleansed CT. A CT without tagged fluid writes none either.
#[test]
fn prep_cleanses_a_tagged_exam_unless_told_not_to() {
    let dir = scratch("cleanse");
    let ct = dir.join("tagged.nii.gz");
    small_colon(&ct, &["--tagged-fluid"]);
    let out = dir.join("on");
    let o = voyage(&[
        "prep",
        ct.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(
        j["cleanse"]["tagged_voxels"].as_u64().unwrap() > 500,
        "{}",
        j["cleanse"]
    );
    let (air, fluid) = (
        j["surface_roughness"]["air_deg"].as_f64().unwrap(),
        j["surface_roughness"]["fluid_deg"].as_f64().unwrap(),
    );
    assert!(
        fluid <= 1.5 * air,
        "roughness {fluid}° where fluid lay, {air}° in air"
    );
    assert!(j["timings_ms"]["cleanse"].as_f64().is_some());
    let info = voyage(&[
        "info",
        out.join("cleansed.nii.gz").to_str().unwrap(),
        "--json",
    ]);
    assert!(info.status.success(), "{}", text(&info));
    let (a, b): (serde_json::Value, serde_json::Value) = (
        serde_json::from_slice(&info.stdout).unwrap(),
        serde_json::from_slice(&voyage(&["info", ct.to_str().unwrap(), "--json"]).stdout).unwrap(),
    );
    assert_eq!(a["dims"], b["dims"]);
    // The same folder again, without cleansing: the tagged run's cleansed CT does not stay
    // beside the new lumen, a stopped run's staging folder goes, the user's own file stays.
    let kept = out.clone();
    let stale = kept.join(".voyage-prep-4000000000");
    std::fs::create_dir_all(&stale).unwrap();
    std::fs::write(stale.join("lumen.nii.gz"), b"half written").unwrap();
    std::fs::write(kept.join("notes.txt"), b"mine").unwrap();
    let o = voyage(&[
        "prep",
        ct.to_str().unwrap(),
        "--out",
        kept.to_str().unwrap(),
        "--json",
        "--no-cleanse",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let k: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(k["cleanse"].is_null() && !kept.join("cleansed.nii.gz").exists());
    assert!(!stale.exists() && kept.join("notes.txt").exists());
    assert!(
        k["surface_roughness"]["fluid_deg"].as_f64().unwrap() > fluid,
        "uncleansed {} vs {fluid}",
        k["surface_roughness"]
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// An output folder that cannot take the exports is refused before the input is even read:
/// a file in its place used to fail after the whole preprocessing.
#[test]
fn an_unusable_out_folder_is_refused_first() {
    let dir = scratch("outfirst");
    let in_the_way = dir.join("taken");
    std::fs::write(&in_the_way, b"a file").unwrap();
    for out in [in_the_way.clone(), in_the_way.join("sub")] {
        let o = voyage(&[
            "prep",
            dir.join("no-such-input.nii.gz").to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        let t = text(&o);
        assert!(!o.status.success(), "{t}");
        assert!(
            t.contains("taken") && t.contains("is not a folder") && !t.contains("no-such-input"),
            "{t}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Preprocessing a full colon stays within 3× the CT's size while it runs and writes its
/// exports. colon-a is a 512×512×321 mask, held as 16-bit values like any CT (160.5 MiB); the
/// process's peak resident memory counts everything, the loaded input included.
#[test]
fn prep_of_a_full_colon_stays_within_three_times_the_ct() {
    let Some(data) = shared_data() else { return };
    let dir = scratch("prep-memory");
    let input = data.join("masks/colon-a.nii.gz");
    let o = voyage(&[
        "prep",
        input.to_str().unwrap(),
        "--out",
        dir.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let ct_mib = (512 * 512 * 321 * 2) as f64 / (1u64 << 20) as f64;
    let peak = j["peak_rss_mb"].as_f64().unwrap();
    assert!(
        peak <= 3.0 * ct_mib,
        "peak {peak:.0} MiB, budget {:.0} MiB",
        3.0 * ct_mib
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn demo_makes_preprocesses_and_checks_the_phantom() {
    let dir = scratch("demo");
    let o = voyage(&[
        "demo",
        "--headless",
        "--small",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    let dice: f64 = out
        .lines()
        .find(|l| l.contains("Dice"))
        .and_then(|l| l.split_whitespace().nth(4))
        .and_then(|d| d.parse().ok())
        .unwrap_or(0.0);
    assert!(dice > 0.97, "{out}");
    for f in [
        "colon.nii.gz",
        "colon.json",
        "colon.lumen.nii.gz",
        "prep/centerline.json",
        "prep/surface.ply",
    ] {
        assert!(dir.join(f).is_file(), "{f} missing");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn prep_of_a_chest_ct_says_there_is_no_colon() {
    let Some(data) = shared_data() else { return };
    let dir = scratch("chest");
    let o = voyage(&[
        "prep",
        data.join("dicom/chest-reversed").to_str().unwrap(),
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("no colon lumen") && err.contains("chest-reversed"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert_private(&o);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn fly_reports_both_directions_and_writes_a_trajectory() {
    let dir = scratch("fly");
    let ct = dir.join("colon.nii.gz");
    small_colon(&ct, &[]);
    let traj = dir.join("trajectory.json");
    let o = voyage(&[
        "fly",
        ct.to_str().unwrap(),
        "--direction",
        "both",
        "--out",
        traj.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    for d in ["forward", "backward"] {
        let f = &j["directions"][d];
        for key in [
            "reached",
            "frames",
            "sim_seconds",
            "min_wall_distance_mm",
            "mean_wall_distance_mm",
            "stalls",
            "path_length_mm",
            "step_ns",
        ] {
            assert!(!f[key].is_null(), "{d}.{key} missing from {f}");
        }
        assert_eq!(f["reached"], true, "{d}: {f}");
        assert!(f["min_wall_distance_mm"].as_f64().unwrap() >= 1.0);
    }
    // The trajectory holds one pose per frame (plus the start) for each direction.
    let poses = voyage_export::trajectory::read_poses(&traj).unwrap();
    assert_eq!(poses.len(), 2);
    assert_eq!(
        poses[0].len() as u64,
        j["directions"]["forward"]["frames"].as_u64().unwrap() + 1
    );
    // A flight that falls short fails the command and says so on stderr; the JSON is still
    // printed, with reached false.
    let short = voyage(&["fly", ct.to_str().unwrap(), "--max-seconds", "2", "--json"]);
    let err = String::from_utf8_lossy(&short.stderr);
    assert!(!short.status.success(), "a flight that fell short exited 0");
    assert!(
        err.contains("forward flight stopped") && err.contains("short of its goal"),
        "{err}"
    );
    let j: serde_json::Value = serde_json::from_slice(&short.stdout).unwrap();
    assert_eq!(j["directions"]["forward"]["reached"], false);
    // Bad physics is refused on one line, before any work.
    let bad = voyage(&["fly", ct.to_str().unwrap(), "--cs=-1"]);
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        err.contains("--cs") && err.trim().lines().count() == 1,
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

fn png(path: &Path) -> image::RgbaImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgba8()
}

#[test]
fn render_movie_and_bench_render_on_the_small_phantom() {
    let dir = scratch("render");
    let ct = dir.join("colon.nii.gz");
    small_colon(&ct, &[]);
    let ct = ct.to_str().unwrap();
    // One frame of the flight on each renderer: same size, nearly the same picture.
    let cpu = dir.join("cpu.png");
    let gpu = dir.join("gpu.png");
    let o = voyage(&[
        "render",
        ct,
        "--frame",
        "40",
        "--out",
        cpu.to_str().unwrap(),
        "--width",
        "320",
        "--height",
        "240",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let o = voyage(&[
        "render",
        ct,
        "--frame",
        "40",
        "--out",
        gpu.to_str().unwrap(),
        "--width",
        "320",
        "--height",
        "240",
        "--gpu",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let (a, b) = (png(&cpu), png(&gpu));
    assert_eq!(a.dimensions(), (320, 240));
    assert_eq!(b.dimensions(), (320, 240));
    let lit = a.pixels().filter(|p| p[0] > 20).count();
    assert!(
        lit > 320 * 240 / 2,
        "the frame is mostly dark: {lit} lit pixels"
    );
    let diff: f64 = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(x, y)| (*x as f64 - *y as f64).abs())
        .sum::<f64>()
        / a.as_raw().len() as f64;
    assert!(
        diff < 2.0,
        "CPU and GPU frames differ by {diff:.2} levels on average"
    );
    // A pose from the flight's trajectory gives the same frame.
    let traj = dir.join("t.json");
    let o = voyage(&[
        "fly",
        ct,
        "--direction",
        "forward",
        "--out",
        traj.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let pose = voyage_export::trajectory::read_poses(&traj).unwrap()[0][40];
    let pose_arg = pose.to_array().map(|v| format!("{v}")).join(",");
    let again = dir.join("pose.png");
    let o = voyage(&[
        "render",
        ct,
        "--pose",
        &pose_arg,
        "--out",
        again.to_str().unwrap(),
        "--width",
        "320",
        "--height",
        "240",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(png(&again), a);
    // Errors: a frame past the end, a bad pose, nothing written.
    let refused = |args: &[&str], needle: &str| {
        let x = dir.join("x.png");
        let o = voyage(&[&["render", ct], args, &["--out", x.to_str().unwrap()]].concat());
        assert!(
            !o.status.success() && String::from_utf8_lossy(&o.stderr).contains(needle),
            "{}",
            text(&o)
        );
    };
    refused(&["--frame", "999999"], "frames");
    refused(&["--pose", "1,2,3"], "seven");
    assert!(!dir.join("x.png").exists());
    // A short movie.
    let movie = dir.join("movie");
    let o = voyage(&[
        "movie",
        ct,
        "--out",
        movie.to_str().unwrap(),
        "--max-frames",
        "4",
        "--every",
        "10",
        "--no-mp4",
        "--width",
        "64",
        "--height",
        "64",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    for i in 0..4 {
        assert_eq!(
            png(&movie.join(format!("frame_{i:05}.png"))).dimensions(),
            (64, 64)
        );
    }
    assert!(!movie.join("frame_00004.png").exists());
    // bench render --json: the fields the issue names, and exactness.
    let o = voyage(&[
        "bench", "render", ct, "--frames", "15", "--random", "10", "--size", "128", "--json",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["exact"], true, "{j}");
    assert_eq!(j["frames"], 40);
    for s in ["all", "lg", "paper", "ours"] {
        let v = &j["strategies"][s];
        for key in [
            "mean_triangles",
            "max_triangles",
            "ratio_to_all",
            "cpu_fps",
            "gpu_fps_512",
            "gpu_fps_1024",
        ] {
            assert!(v[key].is_number(), "{s}.{key} missing: {v}");
        }
    }
    assert!(
        j["strategies"]["ours"]["mean_triangles"].as_f64().unwrap()
            < j["strategies"]["all"]["mean_triangles"].as_f64().unwrap()
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Issue 24, item 8: a mask stored as 0/255 is taken as a mask; labels 0/1/2 without --mask
/// are named as a label mask (not "is this a CT colonography?"); with --mask the labels
/// merged are said.
#[test]
fn label_masks_are_told_from_cts() {
    let dir = scratch("labels");
    let ct = dir.join("colon.nii.gz");
    let truth = dir.join("truth.json");
    small_colon(&ct, &["--truth", truth.to_str().unwrap()]);
    let lumen = voyage_io::load(&dir.join("truth.lumen.nii.gz"), &Default::default())
        .unwrap()
        .volume;
    let remapped = |name: &str, f: &dyn Fn(usize, i16) -> i16| {
        let mut v = lumen.clone();
        for (i, x) in v.data_mut().iter_mut().enumerate() {
            *x = f(i, *x);
        }
        let path = dir.join(name);
        voyage_io::nifti::save(&path, &v).unwrap();
        path
    };
    let out = dir.join("out");
    let prep = |path: &std::path::Path, mask: bool| {
        let mut args = vec![
            "prep",
            path.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        if mask {
            args.push("--mask");
        }
        voyage(&args)
    };
    // 0/255: a mask, found as one.
    let m255 = remapped("m255.nii.gz", &|_, x| x * 255);
    let o = prep(&m255, false);
    assert!(o.status.success(), "{}", text(&o));
    // 0/1/2 (the lumen split in two labels by the voxel's parity): refused as a CT, with the
    // way out named.
    let labels = remapped("labels.nii.gz", &|i, x| {
        if x > 0 { 1 + (i % 2) as i16 } else { 0 }
    });
    let o = prep(&labels, false);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("label mask") && err.contains("--mask") && err.contains("0, 1, 2"),
        "{err}"
    );
    assert!(!err.contains("CT colonography"), "{err}");
    let o = prep(&labels, true);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{}", text(&o));
    assert!(err.contains("mask labels 1, 2 merged"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn coverage_reports_json_and_reads_with_glances_unless_told_not_to() {
    let dir = scratch("coverage");
    let ct = dir.join("colon.nii.gz");
    small_colon(&ct, &[]);
    let read = |extra: &[&str]| {
        let mut args = vec!["coverage", ct.to_str().unwrap(), "--json"];
        args.extend_from_slice(extra);
        let o = voyage(&args);
        assert!(o.status.success(), "{}", text(&o));
        serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap()
    };
    let (with, without) = (read(&[]), read(&["--no-glances"]));
    let pct = |j: &serde_json::Value, k: &str| j[k].as_f64().unwrap();
    for j in [&with, &without] {
        let [one, two, after] =
            ["one_way_pct", "two_way_pct", "after_review_pct"].map(|k| pct(j, k));
        assert!(one < two && two <= after && after <= 100.0, "{j}");
        assert_eq!(j["flights_reached"]["forward"], true);
        for p in j["unseen_patches"].as_array().unwrap() {
            assert!(p["area_mm2"].as_f64().unwrap() >= 30.0, "{p}");
            assert_eq!(p["center_lps_mm"].as_array().unwrap().len(), 3);
            assert!(p["arc_mm"].as_f64().is_some_and(|a| a >= 0.0), "{p}");
            assert_eq!(p["pose"].as_array().map(|a| a.len()), Some(7), "{p}");
        }
        // What the review left is listed where it lies, and is no more than it left unseen.
        let left = j["left_after_review"].as_array().unwrap();
        assert_eq!(
            Some(left.len() as u64),
            j["patches_left_after_review"].as_u64()
        );
        let unseen_mm2 = (100.0 - after) / 100.0 * pct(j, "surface_mm2");
        let left_mm2: f64 = left.iter().map(|p| p["area_mm2"].as_f64().unwrap()).sum();
        assert!(
            left_mm2 <= unseen_mm2 + 1e-6,
            "{left_mm2} of {unseen_mm2} mm²"
        );
        for p in left {
            assert!(p["area_mm2"].as_f64().unwrap() >= 30.0, "{p}");
            assert!(p["segment"].as_str().is_some(), "{p}");
        }
    }
    // The glances are frames shown beside the same flight's: they only add to what it saw.
    let glances = |j: &serde_json::Value| -> Vec<u64> {
        j["glances"]
            .as_array()
            .unwrap()
            .iter()
            .map(|g| g.as_u64().unwrap())
            .collect()
    };
    assert!(glances(&with).iter().all(|&g| g > 0), "{with}");
    assert_eq!(glances(&without), [0, 0]);
    assert_eq!(with["options"]["look_around"], true);
    assert_eq!(without["options"]["look_around"], false);
    assert!(pct(&with, "one_way_pct") > pct(&without, "one_way_pct"));
    assert!(pct(&with, "two_way_pct") >= pct(&without, "two_way_pct"));
    // A lens wider than the renderer's is refused on one line, before any work.
    let bad = voyage(&["coverage", ct.to_str().unwrap(), "--fov", "170"]);
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        !bad.status.success() && err.contains("--fov") && err.trim().lines().count() == 1,
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The report says which series was read (its number and slices, never its free-text
/// description, which can hold a name) and the corrections made by hand, each in the row of
/// the segment it lies in.
#[test]
fn the_report_names_the_series_and_the_corrections_by_hand() {
    let dir = scratch("report-exam");
    let (series, out) = (small_series(&dir), dir.join("out"));
    let slices = std::fs::read_dir(&series).unwrap().count();
    // A seed in the colon's own gas: the colon found is the same, and the seed is said.
    let prep = voyage(&[
        "prep",
        "--json",
        series.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(prep.status.success(), "{}", text(&prep));
    let j: serde_json::Value = serde_json::from_slice(&prep.stdout).unwrap();
    let anchor = &j["segments"][0]["anchor_lps_mm"];
    let seed = format!("{},{},{}", anchor[0], anchor[1], anchor[2]);
    let findings = dir.join("findings.json");
    std::fs::write(&findings, r#"{"markers": [], "measurements": []}"#).unwrap();
    let report = dir.join("report");
    let o = voyage(&[
        "report",
        series.to_str().unwrap(),
        "--seed",
        &seed,
        "--findings",
        findings.to_str().unwrap(),
        "--no-coverage",
        "--out",
        report.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let html = std::fs::read_to_string(report.join("report.html")).unwrap();
    assert!(
        html.contains(&format!(
            "Study: series &middot; CT series 1, {slices} slices (DICOM) &middot; voyage"
        )),
        "{}",
        &html[html.find("<p class=\"study\"").unwrap()..][..200]
    );
    assert!(
        !html.contains("voyage volume"),
        "the series description was printed"
    );
    let table = &html[html
        .find("<table id=\"segments\">")
        .expect("segments table")..];
    let row = table
        .split("<tr>")
        .find(|r| r.contains("gas taken in as colon at LPS ("))
        .expect("the seed in a segment's row");
    assert!(row.starts_with("<td>"), "{row}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Issue 39: a folder holding the exam supine and prone is opened as an exam: `info` names
/// both positions, `prep` exports each with the link of their centerlines, `coverage` reads
/// both and counts mucosa seen in either.
#[test]
fn an_exam_of_two_positions_is_prepared_and_read_in_both() {
    let dir = scratch("pair");
    let exam = dir.join("exam");
    let made = voyage(&[
        "phantom",
        "colon",
        "--pair",
        "--small",
        "--tagged-fluid",
        "--out",
        dir.join("p.nii.gz").to_str().unwrap(),
        "--truth",
        dir.join("p.json").to_str().unwrap(),
        "--dicom",
        exam.to_str().unwrap(),
    ]);
    assert!(made.status.success(), "{}", text(&made));
    for f in [
        "p-supine.nii.gz",
        "p-prone.nii.gz",
        "p-supine.json",
        "p-prone.json",
        "p.json",
    ] {
        assert!(dir.join(f).exists(), "{f} not written");
    }
    let info = voyage(&["info", exam.to_str().unwrap(), "--json"]);
    let info: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
    let positions: Vec<&str> = info["exam_positions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["position"].as_str().unwrap())
        .collect();
    assert_eq!(positions, ["HFS", "HFP"]);

    let out = dir.join("prep");
    let prep = voyage(&[
        "prep",
        exam.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(prep.status.success(), "{}", text(&prep));
    let summary: serde_json::Value = serde_json::from_slice(&prep.stdout).unwrap();
    assert_eq!(summary["positions"][0]["position"], "supine");
    assert_eq!(summary["positions"][1]["position"], "prone");
    assert_eq!(summary["link"]["anchored_at_flexures"], true);
    for p in ["supine", "prone"] {
        assert!(out.join(p).join("centerline.json").exists(), "{p}");
    }
    let link: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("link.json")).unwrap()).unwrap();
    let arcs = link["arc_mm"].as_array().unwrap();
    assert_eq!(
        arcs[0].as_array().unwrap().len(),
        arcs[1].as_array().unwrap().len()
    );

    let cov = voyage(&["coverage", exam.to_str().unwrap(), "--json"]);
    assert!(cov.status.success(), "{}", text(&cov));
    let cov: serde_json::Value = serde_json::from_slice(&cov.stdout).unwrap();
    let one_way = &cov["both_positions"]["one_way"];
    let pct = |v: &serde_json::Value| v.as_f64().unwrap();
    assert!(
        pct(&one_way["combined_pct"]) > pct(&one_way["a_pct"]).max(pct(&one_way["b_pct"])),
        "{one_way}"
    );
    assert!(
        pct(&cov["both_positions"]["after_review"]["combined_pct"]) >= 99.0,
        "{cov}"
    );
    assert_eq!(cov["positions"].as_array().unwrap().len(), 2);
    // A point is of one position: with two it is refused, asking for --series.
    let seeded = voyage(&[
        "prep",
        exam.to_str().unwrap(),
        "--seed",
        "100,100,100",
        "--out",
        dir.join("seeded").to_str().unwrap(),
    ]);
    assert!(!seeded.status.success());
    assert!(text(&seeded).contains("--series"), "{}", text(&seeded));
    // A report over both positions needs their findings: none found is an error that names
    // where it looked, never an empty report.
    let report = voyage(&[
        "report",
        exam.to_str().unwrap(),
        "--findings",
        dir.join("nothing").to_str().unwrap(),
        "--out",
        dir.join("report").to_str().unwrap(),
        "--no-coverage",
    ]);
    assert!(!report.status.success());
    assert!(
        text(&report).contains("supine/findings.json"),
        "{}",
        text(&report)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
