//! DICOM reading and writing: the real series and test files in `../shared/data/dicom` (skipped
//! when absent), and synthetic series written by `dicom_write` (always run).

/// As the `voyage` binary: what a DICOM parser may allocate for one file is bounded.
#[global_allocator]
static ALLOCATOR: voyage_io::GuardedAllocator = voyage_io::GuardedAllocator;

use std::{
    path::{Path, PathBuf},
    sync::atomic::{AtomicUsize, Ordering},
};

use dicom_core::{
    DataElement, VR,
    value::{DataSetSequence, PrimitiveValue},
};
use dicom_dictionary_std::tags;
use dicom_object::{InMemDicomObject, open_file};
use glam::{DMat3, DVec3};
use voyage_core::{Geometry, Volume};
use voyage_io::{
    LoadOptions, Loaded, dicom,
    dicom_write::{SeriesWriteOptions, write_series, write_series_with},
};

// ---------------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------------

use voyage_phantom::fixtures::shared_data as data_dir;

/// A folder under the system temp dir, removed when dropped.
struct TempDir(PathBuf);

impl TempDir {
    fn new(tag: &str) -> TempDir {
        static COUNTER: AtomicUsize = AtomicUsize::new(0);
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let p = std::env::temp_dir().join(format!(
            "voyage-dicom-test-{tag}-{}-{n}",
            std::process::id()
        ));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir_all(&p).unwrap();
        TempDir(p)
    }
    fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn opts() -> LoadOptions {
    LoadOptions::default()
}

fn files_in(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    v.sort();
    v
}

/// A volume with every voxel distinct-ish, including the i16 extremes.
fn synthetic(
    dims: [usize; 3],
    spacing: [f64; 3],
    origin: [f64; 3],
    direction: DMat3,
) -> Volume<i16> {
    let mut g = Geometry::new(dims, spacing, origin).unwrap();
    g.set_direction_mat(direction);
    let n = g.len();
    let mut data: Vec<i16> = (0..n)
        .map(|i| ((i * 7919 + i / 97) % 4000) as i16 - 1500)
        .collect();
    data[0] = i16::MIN;
    data[n - 1] = i16::MAX;
    Volume::from_vec(g, data).unwrap()
}

fn oblique() -> DMat3 {
    DMat3::from_axis_angle(DVec3::new(1.0, 2.0, 3.0).normalize(), 0.7)
}

fn assert_same_geometry(a: &Geometry, b: &Geometry) {
    assert_eq!(a.dims, b.dims);
    for c in 0..3 {
        assert!(
            (a.spacing[c] - b.spacing[c]).abs() < 1e-6,
            "spacing {:?} vs {:?}",
            a.spacing,
            b.spacing
        );
        assert!(
            (a.origin[c] - b.origin[c]).abs() < 1e-6,
            "origin {:?} vs {:?}",
            a.origin,
            b.origin
        );
        for r in 0..3 {
            assert!(
                (a.direction[r][c] - b.direction[r][c]).abs() < 1e-6,
                "direction {:?} vs {:?}",
                a.direction,
                b.direction
            );
        }
    }
}

fn err_text(r: voyage_core::Result<Loaded>) -> String {
    match r {
        Ok(l) => panic!("expected an error, loaded {:?}", l.volume.dims()),
        Err(e) => e.to_string(),
    }
}

/// Rewrites one DICOM file after `edit` changed its data set.
fn edit_file(path: &Path, edit: impl FnOnce(&mut InMemDicomObject)) {
    let mut obj = open_file(path).unwrap();
    edit(&mut obj);
    obj.write_to_file(path).unwrap();
}

fn put_ds(obj: &mut InMemDicomObject, tag: dicom_core::Tag, value: &str) {
    obj.put(DataElement::new(tag, VR::DS, PrimitiveValue::from(value)));
}

fn put_us(obj: &mut InMemDicomObject, tag: dicom_core::Tag, value: u16) {
    obj.put(DataElement::new(tag, VR::US, PrimitiveValue::from(value)));
}

fn put_pixels(obj: &mut InMemDicomObject, words: Vec<u16>) {
    obj.put(DataElement::new(
        tags::PIXEL_DATA,
        VR::OW,
        PrimitiveValue::U16(words.into()),
    ));
}

// ---------------------------------------------------------------------------------------------
// Real series
// ---------------------------------------------------------------------------------------------

#[test]
fn chest_reversed_is_sorted_by_position_not_by_number() {
    let Some(data) = data_dir() else { return };
    let dir = data.join("dicom/chest-reversed");
    let l = dicom::load_dir(&dir, &opts()).unwrap();
    let g = l.volume.geometry();
    assert_eq!(g.dims, [512, 512, 40]);
    assert_eq!(g.spacing, [0.9765625, 0.9765625, 2.0]);
    assert_eq!(g.orientation_code(), "LPS");
    // z ascends along k: slice 0 is the lowest (file 00-slice089.dcm, z = -62.5).
    assert_eq!(g.origin, [-250.0, -164.0, -62.5]);
    assert!((g.index_to_patient(DVec3::new(0.0, 0.0, 39.0)).z - 15.5).abs() < 1e-9);
    let lowest = dicom::load_file(&dir.join("00-slice089.dcm"), &opts()).unwrap();
    let highest = dicom::load_file(&dir.join("00-slice050.dcm"), &opts()).unwrap();
    assert_eq!(l.volume.slice_k(0), lowest.volume.slice_k(0));
    assert_eq!(l.volume.slice_k(39), highest.volume.slice_k(0));
    // 12-bit unsigned + intercept −1024: air outside the body and in the lungs.
    let (lo, hi) = l.volume.min_max();
    assert!((-1100..=-900).contains(&lo), "min {lo}");
    assert!(hi > 1000, "max {hi}");
    let air = l.volume.data().iter().filter(|&&v| v < -900).count() as f64 / g.len() as f64;
    assert!(air > 0.2, "air fraction {air}");
    assert_eq!(l.meta.files, 40);
    assert_eq!(l.meta.modality.as_deref(), Some("CT"));
    assert_eq!(l.meta.transfer_syntaxes, ["Implicit VR Little Endian"]);
}

#[test]
fn abdomen_j2k_series() {
    let Some(data) = data_dir() else { return };
    let l = dicom::load_dir(&data.join("dicom/abdomen-j2k"), &opts()).unwrap();
    let g = l.volume.geometry();
    assert_eq!(g.dims, [512, 512, 20]);
    assert!((g.spacing[0] - 0.9765625).abs() < 1e-9 && (g.spacing[1] - 0.9765625).abs() < 1e-9);
    assert!(
        (g.spacing[2] - 2.0).abs() < 1e-9,
        "slices are 2 mm apart (3 mm thick)"
    );
    assert_eq!(g.origin[2], -804.5);
    assert!(l.meta.transfer_syntaxes[0].contains("JPEG 2000"));
    // Intercept −1024 applied: outside air is about −1000 HU, not about 0.
    let (lo, _) = l.volume.min_max();
    assert!((-1100..=-950).contains(&lo), "min {lo}");
    let air = l
        .volume
        .data()
        .iter()
        .filter(|&&v| (-1100..=-900).contains(&v))
        .count();
    assert!(air as f64 > 0.1 * g.len() as f64);
    // These files have an empty SeriesInstanceUID: loaded all the same, reported as none.
    assert_eq!(l.meta.series_uid, None);
}

#[test]
fn head_gantry_tilt_with_uneven_gaps_is_refused() {
    let Some(data) = data_dir() else { return };
    let msg = err_text(dicom::load_dir(
        &data.join("dicom/head-gantry-tilt"),
        &opts(),
    ));
    assert!(msg.contains("uneven slice gaps"), "{msg}");
    assert!(msg.contains("tilt of 18.5°"), "{msg}");
    assert!(msg.contains("24.dcm") && msg.contains("25.dcm"), "{msg}");
}

/// Bone centroid of a slice in patient coordinates.
fn bone_centroid(v: &Volume<i16>, k: usize) -> DVec3 {
    let g = v.geometry();
    let (mut sum, mut n) = (DVec3::ZERO, 0.0);
    for j in 0..g.dims[1] {
        for i in 0..g.dims[0] {
            if v.get(i, j, k) > 300 {
                sum += g.index_to_patient(DVec3::new(i as f64, j as f64, k as f64));
                n += 1.0;
            }
        }
    }
    sum / n
}

#[test]
fn head_gantry_tilt_is_corrected_where_gaps_are_even() {
    let Some(data) = data_dir() else { return };
    // Slices 01..14 are evenly spaced (4 mm along the normal, 4.22 mm along z).
    let tmp = TempDir::new("tilt");
    for n in 1..=14 {
        let name = format!("{n:02}.dcm");
        std::fs::copy(
            data.join("dicom/head-gantry-tilt").join(&name),
            tmp.path().join(&name),
        )
        .unwrap();
    }
    let l = dicom::load_dir(tmp.path(), &opts()).unwrap();
    let g = l.volume.geometry();
    assert!(
        l.meta
            .notes
            .iter()
            .any(|n| n.contains("gantry tilt of 18.5° corrected")),
        "{:?}",
        l.meta.notes
    );
    // k runs along the slice normal, 4.22 × cos 18.5° apart; the grid is orthonormal and was
    // widened along j by the total drift (13 × 4.22 × sin 18.5° ≈ 17.4 mm ≈ 36 rows).
    assert!(
        (g.spacing[2] - 4.22 * 0.9483237).abs() < 1e-3,
        "{:?}",
        g.spacing
    );
    assert_eq!(g.dims, [512, 548, 14]);
    let m = g.direction_mat();
    assert!(
        (m.transpose() * m - DMat3::IDENTITY)
            .abs()
            .to_cols_array()
            .iter()
            .all(|&e| e < 1e-9)
    );
    assert!((m.determinant() - 1.0).abs() < 1e-9);
    // Every slice's bone lies where the original slice had it, in patient coordinates.
    for k in [0, 6, 13] {
        let original =
            dicom::load_file(&tmp.path().join(format!("{:02}.dcm", k + 1)), &opts()).unwrap();
        let want = bone_centroid(&original.volume, 0);
        let got = bone_centroid(&l.volume, k);
        assert!((want - got).length() < 0.3, "slice {k}: {want} vs {got}");
    }
}

// ---------------------------------------------------------------------------------------------
// Transfer syntaxes
// ---------------------------------------------------------------------------------------------

enum Expect {
    Exact,
    /// Lossy: max and mean absolute HU error against the uncompressed file.
    Within(i32, f64),
    /// Refused; the message must contain these.
    Refused(&'static [&'static str]),
}

#[test]
fn every_transfer_syntax_decodes_to_the_reference_hu_or_is_refused_clearly() {
    let Some(data) = data_dir() else { return };
    let dir = data.join("dicom/transfer-syntaxes");
    let reference = dicom::load_file(
        &dir.join("CTImage.dcm_LittleEndianExplicitTransferSyntax_1.2.840.10008.1.2.1.dcm"),
        &opts(),
    )
    .unwrap();
    let cases: &[(&str, Expect)] = &[
        ("CTImage.dcm", Expect::Exact),
        ("LittleEndianImplicit", Expect::Exact),
        ("BigEndianExplicit", Expect::Exact),
        ("DeflatedExplicitVRLittleEndian", Expect::Exact),
        ("RLELossless", Expect::Exact),
        ("JPEGProcess14TransferSyntax", Expect::Exact),
        ("JPEGProcess14SV1", Expect::Exact),
        ("JPEGLSLossless", Expect::Exact),
        ("JPEG2000LosslessOnly", Expect::Exact),
        // 8 bits stored with RescaleSlope 32.1: HU in steps of 32, plus the JPEG error.
        ("JPEGProcess1Transfer", Expect::Within(70, 21.0)),
        // Near-lossless JPEG-LS with NEAR = 1.
        ("JPEGLSLossy", Expect::Within(1, 0.75)),
        ("JPEG2000Transfer", Expect::Within(8, 1.0)),
        (
            "JPEGProcess2_4",
            Expect::Refused(&[
                "JPEG Extended (Process 2 & 4)",
                "12-bit lossy JPEG is not supported",
            ]),
        ),
        (
            "JPEGProcess6_8",
            Expect::Refused(&["1.2.840.10008.1.2.4.53", "Process 6 & 8", "not supported"]),
        ),
        (
            "JPEGProcess10_12",
            Expect::Refused(&["1.2.840.10008.1.2.4.55", "Process 10 & 12", "not supported"]),
        ),
    ];
    for (pattern, expect) in cases {
        let path = files_in(&dir)
            .into_iter()
            .find(|p| {
                let name = p.file_name().unwrap().to_string_lossy().into_owned();
                if *pattern == "CTImage.dcm" {
                    name == "CTImage.dcm"
                } else {
                    name.contains(pattern)
                }
            })
            .unwrap_or_else(|| panic!("no file for {pattern}"));
        let result = dicom::load_file(&path, &opts());
        match expect {
            Expect::Exact => {
                let l = result.unwrap_or_else(|e| panic!("{pattern}: {e}"));
                assert_eq!(
                    l.volume.geometry(),
                    reference.volume.geometry(),
                    "{pattern}"
                );
                assert!(
                    l.volume.data() == reference.volume.data(),
                    "{pattern}: HU differ from the reference"
                );
            }
            Expect::Within(max, mean) => {
                let l = result.unwrap_or_else(|e| panic!("{pattern}: {e}"));
                assert_eq!(l.volume.dims(), reference.volume.dims());
                let errs: Vec<i32> = l
                    .volume
                    .data()
                    .iter()
                    .zip(reference.volume.data())
                    .map(|(a, b)| (*a as i32 - *b as i32).abs())
                    .collect();
                let got_max = *errs.iter().max().unwrap();
                let got_mean = errs.iter().map(|&e| e as f64).sum::<f64>() / errs.len() as f64;
                assert!(
                    got_max <= *max && got_mean <= *mean,
                    "{pattern}: max {got_max} mean {got_mean:.3}"
                );
                assert!(got_max > 0, "{pattern} is lossy yet exact?");
                assert!(
                    l.meta.notes.iter().any(|n| n.contains("lossy")),
                    "{pattern}: {:?}",
                    l.meta.notes
                );
            }
            Expect::Refused(words) => {
                let msg = err_text(result);
                assert!(
                    msg.contains(path.file_name().unwrap().to_str().unwrap()),
                    "{msg}"
                );
                assert!(
                    msg.contains("cannot decode pixel data (transfer syntax"),
                    "{msg}"
                );
                for w in *words {
                    assert!(msg.contains(w), "{pattern}: '{w}' not in: {msg}");
                }
            }
        }
    }
}

#[test]
fn other_jpeg2000_ct_slices_match_an_independent_decoder() {
    let Some(data) = data_dir() else { return };
    let dir = data.join("dicom/transfer-syntaxes");
    // (file, min, max, sum of HU, HU at (256,256) and at column 300 row 100), from pydicom with
    // pylibjpeg-openjpeg.
    for (name, min, max, sum, centre, other) in [
        ("CT1_J2KR", -3024, 1254, -228_407_043i64, -59, 28),
        ("CT2_J2KR", -2048, 1433, -197_733_355, 38, 16),
    ] {
        let l = dicom::load_file(&dir.join(name), &opts()).unwrap();
        assert_eq!(l.volume.dims(), [512, 512, 1]);
        assert_eq!(l.volume.min_max(), (min, max), "{name}");
        assert_eq!(
            l.volume.data().iter().map(|&v| v as i64).sum::<i64>(),
            sum,
            "{name}"
        );
        assert_eq!(l.volume.get(256, 256, 0), centre, "{name}");
        assert_eq!(l.volume.get(300, 100, 0), other, "{name}");
    }
    let ct1 = dicom::load_file(&dir.join("CT1_J2KR"), &opts()).unwrap();
    assert_eq!(ct1.volume.spacing(), [0.661468, 0.661468, 5.0]);
}

#[test]
fn files_without_pixels_or_grayscale_are_refused() {
    let Some(data) = data_dir() else { return };
    let dir = data.join("dicom/transfer-syntaxes");
    let msg = err_text(dicom::load_file(&dir.join("no-pixel-data.dcm"), &opts()));
    assert!(
        msg.contains("no-pixel-data.dcm") && msg.contains("no image"),
        "{msg}"
    );
    // An ultrasound palette image without PixelSpacing: its values are not HU at all.
    let msg = err_text(dicom::load_file(&dir.join("no-pixel-spacing.dcm"), &opts()));
    assert!(
        msg.contains("no-pixel-spacing.dcm") && msg.contains("PALETTE COLOR"),
        "{msg}"
    );
}

// ---------------------------------------------------------------------------------------------
// Broken input
// ---------------------------------------------------------------------------------------------

#[test]
fn broken_files_give_errors_naming_file_and_problem() {
    let Some(data) = data_dir() else { return };
    let dir = data.join("dicom/broken");
    let expected = [
        (
            "MR_truncated.dcm",
            "pixel data truncated: its element announces 8192 bytes and the file holds 8130",
        ),
        ("badVR.dcm", "NumberOfFrames (0028,0008) is '1A'"),
        ("meta_missing_tsyntax.dcm", "no TransferSyntaxUID"),
        ("nested_priv_SQ.dcm", "no image"),
        ("truncated-j2k-slice.dcm", "cut short"),
    ];
    assert_eq!(
        files_in(&dir).len(),
        expected.len(),
        "a new broken file needs an expectation here"
    );
    for (name, problem) in expected {
        let path = dir.join(name);
        let msg = err_text(dicom::load_file(&path, &opts()));
        assert!(msg.contains(name) && msg.contains(problem), "{name}: {msg}");
        let msg = err_text(voyage_io::load(&path, &opts()));
        assert!(msg.contains(name), "{name} via io::load: {msg}");
        let tmp = TempDir::new("broken");
        std::fs::copy(&path, tmp.path().join(name)).unwrap();
        let msg = err_text(dicom::load_dir(tmp.path(), &opts()));
        assert!(msg.contains(name), "folder with {name}: {msg}");
    }
}

#[test]
fn empty_and_non_dicom_folders_are_refused() {
    let tmp = TempDir::new("empty");
    let msg = err_text(dicom::load_dir(tmp.path(), &opts()));
    assert!(msg.contains("no DICOM images in folder"), "{msg}");
    std::fs::write(tmp.path().join("README"), "not an image\n").unwrap();
    std::fs::write(tmp.path().join("notes.txt"), "x".repeat(500)).unwrap();
    let msg = err_text(dicom::load_dir(tmp.path(), &opts()));
    assert!(
        msg.contains("no DICOM images in folder") && msg.contains("2 not DICOM"),
        "{msg}"
    );
    let msg = err_text(dicom::load_file(&tmp.path().join("README"), &opts()));
    assert!(
        msg.contains("README") && msg.contains("not a DICOM file"),
        "{msg}"
    );
}

#[test]
fn cut_files_and_garbage_never_panic() {
    let vol = synthetic([16, 12, 3], [1.0; 3], [0.0; 3], DMat3::IDENTITY);
    let tmp = TempDir::new("cut");
    write_series(tmp.path(), &vol).unwrap();
    let bytes = std::fs::read(tmp.path().join("slice0001.dcm")).unwrap();
    let probe = tmp.path().join("probe");
    std::fs::create_dir_all(&probe).unwrap();
    let file = probe.join("x.dcm");
    // Every cut point in the header, and a sample of cuts and corruptions in the pixel data.
    let cuts: Vec<usize> = (0..bytes.len().min(1400))
        .chain((1400..bytes.len()).step_by(37))
        .collect();
    for cut in cuts {
        std::fs::write(&file, &bytes[..cut]).unwrap();
        if let Err(e) = dicom::load_file(&file, &opts()) {
            assert!(e.to_string().contains("x.dcm"), "cut {cut}: {e}");
        }
    }
    let mut state = 12345u64;
    for round in 0..1000 {
        let mut b = bytes.clone();
        for _ in 0..4 {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let at = 132 + (state >> 33) as usize % 1200;
            b[at] = (state >> 20) as u8;
        }
        std::fs::write(&file, &b).unwrap();
        if let Err(e) = dicom::load_file(&file, &opts()) {
            assert!(e.to_string().contains("x.dcm"), "round {round}: {e}");
        }
    }
}

#[test]
fn huge_dimensions_are_refused_before_allocating() {
    let vol = synthetic([8, 8, 1], [1.0; 3], [0.0; 3], DMat3::IDENTITY);
    let tmp = TempDir::new("huge");
    write_series(tmp.path(), &vol).unwrap();
    let path = tmp.path().join("slice0000.dcm");
    edit_file(&path, |o| {
        put_us(o, tags::ROWS, 65535);
        put_us(o, tags::COLUMNS, 65535);
        o.put(DataElement::new(
            tags::NUMBER_OF_FRAMES,
            VR::IS,
            PrimitiveValue::from("1000"),
        ));
    });
    let msg = err_text(dicom::load_file(&path, &opts()));
    assert!(
        msg.contains("slice0000.dcm") && msg.contains("over the limit"),
        "{msg}"
    );
    edit_file(&path, |o| {
        put_us(o, tags::ROWS, 100);
        put_us(o, tags::COLUMNS, 100);
        o.remove_element(tags::NUMBER_OF_FRAMES);
    });
    let msg = err_text(dicom::load_file(&path, &opts()));
    assert!(
        msg.contains("pixel data truncated: expected 20000 bytes, found 128"),
        "{msg}"
    );
}

/// A pixel data element that announces more bytes than the file holds, though the file holds
/// all the image needs: refused, and the message says what was announced, what is there and
/// what is needed (it used to read "expected 128 bytes, found 128 (the file ends early)").
#[test]
fn an_overlong_pixel_data_element_is_refused_with_its_own_figures() {
    let vol = synthetic([8, 8, 1], [1.0; 3], [0.0; 3], DMat3::IDENTITY);
    let tmp = TempDir::new("overlong");
    write_series(tmp.path(), &vol).unwrap();
    let path = tmp.path().join("slice0000.dcm");
    let mut bytes = std::fs::read(&path).unwrap();
    // The last element is the pixel data: tag, VR, two reserved bytes, then its length.
    let at = bytes
        .windows(4)
        .rposition(|w| w == [0xe0, 0x7f, 0x10, 0x00])
        .unwrap();
    let len_at = at + 8;
    let len = u32::from_le_bytes(bytes[len_at..len_at + 4].try_into().unwrap());
    assert_eq!(len, 128);
    bytes[len_at..len_at + 4].copy_from_slice(&(len + 2).to_le_bytes());
    std::fs::write(&path, &bytes).unwrap();
    let msg = err_text(dicom::load_file(&path, &opts()));
    assert!(
        msg.contains("slice0000.dcm")
            && msg.contains("announces 130 bytes and the file holds 128")
            && msg.contains("needs 128"),
        "{msg}"
    );
}

// ---------------------------------------------------------------------------------------------
// Writing and reading back
// ---------------------------------------------------------------------------------------------

#[test]
fn round_trip_oblique_anisotropic() {
    let vol = synthetic(
        [64, 48, 30],
        [0.7, 0.7, 1.25],
        [-120.5, 33.25, 710.125],
        oblique(),
    );
    let tmp = TempDir::new("roundtrip");
    write_series(tmp.path(), &vol).unwrap();
    assert_eq!(files_in(tmp.path()).len(), 30);
    assert!(
        tmp.path().join("slice0000.dcm").is_file() && tmp.path().join("slice0029.dcm").is_file()
    );
    let l = dicom::load_dir(tmp.path(), &opts()).unwrap();
    assert_same_geometry(l.volume.geometry(), vol.geometry());
    assert!(l.volume.data() == vol.data(), "voxels differ");
    assert_eq!(l.meta.modality.as_deref(), Some("CT"));
    assert_eq!(l.meta.series_description.as_deref(), Some("voyage volume"));
    assert_eq!(l.meta.transfer_syntaxes, ["Explicit VR Little Endian"]);
    assert!(l.meta.notes.is_empty(), "{:?}", l.meta.notes);

    // dicom-rs reads the files as valid Part 10 with the right meta group.
    let obj = open_file(tmp.path().join("slice0007.dcm")).unwrap();
    assert_eq!(
        obj.meta().media_storage_sop_class_uid(),
        "1.2.840.10008.5.1.4.1.1.2"
    );
    assert_eq!(obj.meta().transfer_syntax(), "1.2.840.10008.1.2.1");
    let sop = obj
        .element(tags::SOP_INSTANCE_UID)
        .unwrap()
        .to_str()
        .unwrap()
        .into_owned();
    assert_eq!(obj.meta().media_storage_sop_instance_uid(), sop);
    assert!(sop.starts_with("2.25.") && sop.ends_with(".8") && sop.len() <= 64);
    assert_eq!(
        obj.element(tags::INSTANCE_NUMBER)
            .unwrap()
            .to_int::<i32>()
            .unwrap(),
        8
    );
    assert_eq!(
        obj.element(tags::PATIENT_NAME).unwrap().to_str().unwrap(),
        "Phantom^Voyage"
    );

    // Same volume, same bytes: the UIDs are deterministic.
    let again = TempDir::new("roundtrip-again");
    write_series(again.path(), &vol).unwrap();
    assert_eq!(
        std::fs::read(tmp.path().join("slice0003.dcm")).unwrap(),
        std::fs::read(again.path().join("slice0003.dcm")).unwrap()
    );
}

#[test]
fn sorting_ignores_file_names() {
    let vol = synthetic(
        [20, 16, 12],
        [0.8, 0.9, 2.5],
        [5.0, -7.0, -300.0],
        oblique(),
    );
    let tmp = TempDir::new("shuffle");
    write_series(tmp.path(), &vol).unwrap();
    // Rename to names whose order is a scramble of k, with no extension.
    let files = files_in(tmp.path());
    for (k, f) in files.iter().enumerate() {
        let scrambled = (k * 7 + 3) % files.len();
        std::fs::rename(f, tmp.path().join(format!("IM{scrambled:03}"))).unwrap();
    }
    let l = dicom::load_dir(tmp.path(), &opts()).unwrap();
    assert_same_geometry(l.volume.geometry(), vol.geometry());
    assert!(l.volume.data() == vol.data());
}

#[test]
fn a_missing_slice_is_an_error_naming_the_gap() {
    let vol = synthetic(
        [20, 16, 12],
        [0.8, 0.8, 1.25],
        [0.0, 0.0, 0.0],
        DMat3::IDENTITY,
    );
    let tmp = TempDir::new("gap");
    write_series(tmp.path(), &vol).unwrap();
    std::fs::remove_file(tmp.path().join("slice0005.dcm")).unwrap();
    let msg = err_text(dicom::load_dir(tmp.path(), &opts()));
    assert!(
        msg.contains("1 slice(s) missing") && msg.contains("gap of 2.50 mm"),
        "{msg}"
    );
    assert!(
        msg.contains("slice0004.dcm") && msg.contains("slice0006.dcm"),
        "{msg}"
    );

    // A byte-identical second copy of one slice (exported twice): left out, with a warning.
    let dup = TempDir::new("duplicate");
    write_series(dup.path(), &vol).unwrap();
    std::fs::copy(
        dup.path().join("slice0004.dcm"),
        dup.path().join("extra.dcm"),
    )
    .unwrap();
    let l = dicom::load_dir(dup.path(), &opts()).unwrap();
    assert_eq!(l.volume.dims(), vol.dims());
    assert_eq!(l.volume.data(), vol.data());
    assert!(
        l.meta.warnings.iter().any(|w| w.contains("extra.dcm")
            && w.contains("slice0004.dcm")
            && w.contains("is a byte-identical copy of")),
        "{:?}",
        l.meta.warnings
    );
    // A different slice at the same position: refused.
    edit_file(&dup.path().join("extra.dcm"), |o| {
        put_pixels(o, vec![7; 20 * 16])
    });
    let msg = err_text(dicom::load_dir(dup.path(), &opts()));
    assert!(
        msg.contains("two slices at the same position")
            && msg.contains("slice0004.dcm")
            && msg.contains("extra.dcm"),
        "{msg}"
    );

    // Positions rounded to 0.1 mm, as real series store them: a 0.625 mm series steps 0.6
    // and 0.7 mm. Accepted, the slices placed at the mean gap.
    let fine = synthetic([16, 12, 9], [0.8, 0.8, 0.625], [0.0; 3], DMat3::IDENTITY);
    let rounded = TempDir::new("rounded");
    write_series(rounded.path(), &fine).unwrap();
    for k in 0..9 {
        let z = (k as f64 * 0.625 * 10.0).round() / 10.0;
        edit_file(&rounded.path().join(format!("slice{k:04}.dcm")), |o| {
            put_ds(o, tags::IMAGE_POSITION_PATIENT, &format!("0\\0\\{z}"))
        });
    }
    let l = dicom::load_dir(rounded.path(), &opts()).unwrap();
    assert!(
        (l.volume.spacing()[2] - 0.625).abs() < 0.01,
        "{:?}",
        l.volume.spacing()
    );
    assert_eq!(l.volume.data(), fine.data());

    // Uneven gaps: one slice moved by a third of the spacing.
    let uneven = TempDir::new("uneven");
    write_series(uneven.path(), &vol).unwrap();
    edit_file(&uneven.path().join("slice0007.dcm"), |o| {
        put_ds(o, tags::IMAGE_POSITION_PATIENT, "0\\0\\9.1")
    });
    let msg = err_text(dicom::load_dir(uneven.path(), &opts()));
    assert!(
        msg.contains("uneven slice gaps") && msg.contains("slice0007.dcm"),
        "{msg}"
    );
}

#[test]
fn a_left_handed_volume_comes_back_in_the_same_place() {
    // k pointing against row × column: DICOM has no way to say so, the loader returns the
    // right-handed equivalent (k reversed) with every voxel at the same patient position.
    let flip = DMat3::from_cols(DVec3::X, DVec3::Y, DVec3::NEG_Z);
    let vol = synthetic([10, 8, 6], [1.0, 1.5, 2.0], [1.0, 2.0, 3.0], flip);
    let tmp = TempDir::new("lefthanded");
    write_series(tmp.path(), &vol).unwrap();
    let l = dicom::load_dir(tmp.path(), &opts()).unwrap();
    let (a, b) = (vol.geometry(), l.volume.geometry());
    assert_eq!(b.orientation_code(), "LPS");
    for k in 0..6 {
        for (i, j) in [(0, 0), (9, 7), (3, 4)] {
            let p = a.index_to_patient(DVec3::new(i as f64, j as f64, k as f64));
            let q = b.index_to_patient(DVec3::new(i as f64, j as f64, (5 - k) as f64));
            assert!((p - q).length() < 1e-6);
            assert_eq!(vol.get(i, j, k), l.volume.get(i, j, 5 - k));
        }
    }
}

/// The report's series and exam date come from SeriesNumber and StudyDate; a date that is no
/// date is passed over, and a series without one has none.
#[test]
fn series_number_and_exam_date_are_read() {
    let v = synthetic([8, 8, 6], [1.0; 3], [0.0; 3], DMat3::IDENTITY);
    for (date, want) in [
        (Some("20261127"), Some("2026-11-27")),
        (Some("2026.11.27"), Some("2026-11-27")),
        (Some("20261399"), None),
        (Some("unknown"), None),
        (None, None),
    ] {
        let dir = TempDir::new("exam-date");
        write_series_with(
            dir.path(),
            &v,
            &SeriesWriteOptions {
                series_number: 7,
                study_date: date.map(str::to_string),
                ..Default::default()
            },
        )
        .unwrap();
        let l = dicom::load_dir(dir.path(), &opts()).unwrap();
        assert_eq!(l.meta.series_number, Some(7));
        assert_eq!(l.meta.exam_date.as_deref(), want, "{date:?}");
    }
}

#[test]
fn two_series_pick_the_bigger_unless_told() {
    let big = synthetic([16, 16, 20], [1.0; 3], [0.0; 3], DMat3::IDENTITY);
    let small = synthetic(
        [16, 16, 8],
        [0.5, 0.5, 3.0],
        [10.0, 0.0, 0.0],
        DMat3::IDENTITY,
    );
    let tmp = TempDir::new("twoseries");
    let (a, b) = (TempDir::new("series-a"), TempDir::new("series-b"));
    write_series_with(
        a.path(),
        &big,
        &SeriesWriteOptions {
            series_description: "big".into(),
            series_number: 2,
            uid_seed: 1,
            ..Default::default()
        },
    )
    .unwrap();
    write_series_with(
        b.path(),
        &small,
        &SeriesWriteOptions {
            series_description: "small".into(),
            series_number: 3,
            uid_seed: 2,
            ..Default::default()
        },
    )
    .unwrap();
    for (prefix, dir) in [("a", &a), ("b", &b)] {
        for f in files_in(dir.path()) {
            std::fs::rename(
                &f,
                tmp.path().join(format!(
                    "{prefix}-{}",
                    f.file_name().unwrap().to_string_lossy()
                )),
            )
            .unwrap();
        }
    }
    std::fs::write(tmp.path().join("README.txt"), "two series\n").unwrap();
    let l = dicom::load_dir(tmp.path(), &opts()).unwrap();
    assert_eq!(l.volume.dims(), [16, 16, 20]);
    assert_eq!(l.meta.series_description.as_deref(), Some("big"));
    assert_eq!(l.meta.other_series.len(), 1);
    let other = &l.meta.other_series[0];
    assert_eq!(
        (other.slices, other.description.as_deref()),
        (8, Some("small"))
    );
    assert!(
        l.meta
            .notes
            .iter()
            .any(|n| n.contains("2 series") && n.contains("most slices")),
        "{:?}",
        l.meta.notes
    );
    assert!(
        l.meta.notes.iter().any(|n| n.contains("non-DICOM")),
        "{:?}",
        l.meta.notes
    );

    let chosen = LoadOptions {
        series_uid: Some(other.uid.clone()),
    };
    let l2 = dicom::load_dir(tmp.path(), &chosen).unwrap();
    assert!(l2.volume.data() == small.data());
    assert_same_geometry(l2.volume.geometry(), small.geometry());

    let missing = LoadOptions {
        series_uid: Some("1.2.3.4".into()),
    };
    let msg = err_text(dicom::load_dir(tmp.path(), &missing));
    assert!(
        msg.contains("1.2.3.4 not found")
            && msg.contains(&other.uid)
            && msg.contains(l.meta.series_uid.as_deref().unwrap()),
        "{msg}"
    );
    // The descriptions are free text (a name can be in them): no message quotes them.
    for said in l.meta.notes.iter().chain(&l.meta.warnings).chain([&msg]) {
        assert!(!said.contains("big") && !said.contains("small"), "{said}");
    }
}

#[test]
fn rescale_is_applied_per_slice_with_saturation() {
    let vol = synthetic([12, 10, 5], [1.0; 3], [0.0; 3], DMat3::IDENTITY);
    let tmp = TempDir::new("rescale");
    write_series(tmp.path(), &vol).unwrap();
    edit_file(&tmp.path().join("slice0002.dcm"), |o| {
        put_ds(o, tags::RESCALE_SLOPE, "2.5");
        put_ds(o, tags::RESCALE_INTERCEPT, "-100");
    });
    let l = dicom::load_dir(tmp.path(), &opts()).unwrap();
    for k in 0..5 {
        for (a, b) in l.volume.slice_k(k).iter().zip(vol.slice_k(k)) {
            let want = if k == 2 {
                (*b as f64 * 2.5 - 100.0).round().clamp(-32768.0, 32767.0) as i16
            } else {
                *b
            };
            assert_eq!(*a, want, "slice {k}");
        }
    }
    assert!(
        l.meta.notes.iter().any(|n| n.contains("RescaleSlope 2.5")),
        "{:?}",
        l.meta.notes
    );
}

#[test]
fn stored_bits_are_masked_and_sign_extended() {
    let vol = synthetic([8, 4, 1], [1.0; 3], [0.0; 3], DMat3::IDENTITY);
    let tmp = TempDir::new("bits");
    write_series(tmp.path(), &vol).unwrap();
    let path = tmp.path().join("slice0000.dcm");
    let stored: Vec<u16> = (0..32u16).map(|i| i * 128 + 5).collect(); // 5 ..= 3973, all < 4096
    // 12-bit unsigned with garbage (an overlay) in the top 4 bits, intercept −1024.
    edit_file(&path, |o| {
        put_us(o, tags::BITS_STORED, 12);
        put_us(o, tags::HIGH_BIT, 11);
        put_us(o, tags::PIXEL_REPRESENTATION, 0);
        put_ds(o, tags::RESCALE_INTERCEPT, "-1024");
        put_pixels(o, stored.iter().map(|v| v | 0xA000).collect());
    });
    let l = dicom::load_file(&path, &opts()).unwrap();
    let want: Vec<i16> = stored.iter().map(|&v| v as i16 - 1024).collect();
    assert_eq!(l.volume.data(), want.as_slice());
    // 12-bit signed: 0xFFF is −1, 0x800 is −2048.
    edit_file(&path, |o| {
        put_us(o, tags::PIXEL_REPRESENTATION, 1);
        put_ds(o, tags::RESCALE_INTERCEPT, "0");
        put_pixels(
            o,
            [0xFFFu16, 0x800, 0x7FF, 0x001]
                .iter()
                .cycle()
                .take(32)
                .map(|v| v | 0x5000)
                .collect(),
        );
    });
    let l = dicom::load_file(&path, &opts()).unwrap();
    assert_eq!(&l.volume.data()[..4], &[-1, -2048, 2047, 1]);
    // 8-bit unsigned samples.
    edit_file(&path, |o| {
        put_us(o, tags::BITS_ALLOCATED, 8);
        put_us(o, tags::BITS_STORED, 8);
        put_us(o, tags::HIGH_BIT, 7);
        put_us(o, tags::PIXEL_REPRESENTATION, 0);
        put_ds(o, tags::RESCALE_INTERCEPT, "-1000");
        let bytes: Vec<u8> = (0..32u8).map(|i| i * 8).collect();
        o.put(DataElement::new(
            tags::PIXEL_DATA,
            VR::OB,
            PrimitiveValue::U8(bytes.into()),
        ));
    });
    let l = dicom::load_file(&path, &opts()).unwrap();
    let want: Vec<i16> = (0..32i16).map(|i| i * 8 - 1000).collect();
    assert_eq!(l.volume.data(), want.as_slice());
}

#[test]
fn missing_pixel_spacing_is_refused() {
    let vol = synthetic([8, 8, 3], [1.0; 3], [0.0; 3], DMat3::IDENTITY);
    let tmp = TempDir::new("nospacing");
    write_series(tmp.path(), &vol).unwrap();
    for f in files_in(tmp.path()) {
        edit_file(&f, |o| {
            o.remove_element(tags::PIXEL_SPACING);
        });
    }
    let msg = err_text(dicom::load_dir(tmp.path(), &opts()));
    assert!(msg.contains("PixelSpacing (0028,0030) is missing"), "{msg}");
}

#[test]
fn mismatched_slices_are_refused() {
    let vol = synthetic([8, 8, 4], [1.0; 3], [0.0; 3], DMat3::IDENTITY);
    let tmp = TempDir::new("mismatch");
    write_series(tmp.path(), &vol).unwrap();
    edit_file(&tmp.path().join("slice0001.dcm"), |o| {
        put_ds(o, tags::PIXEL_SPACING, "1\\1.2")
    });
    let msg = err_text(dicom::load_dir(tmp.path(), &opts()));
    assert!(
        msg.contains("slice0001.dcm") && msg.contains("PixelSpacing") && msg.contains("differs"),
        "{msg}"
    );
    edit_file(&tmp.path().join("slice0001.dcm"), |o| {
        put_ds(o, tags::PIXEL_SPACING, "1\\1");
        put_ds(o, tags::IMAGE_ORIENTATION_PATIENT, "1\\0\\0\\0\\0.8\\0.6");
    });
    let msg = err_text(dicom::load_dir(tmp.path(), &opts()));
    assert!(msg.contains("ImageOrientationPatient differs"), "{msg}");
}

#[test]
fn single_slice_and_multi_frame_files() {
    let vol = synthetic(
        [12, 10, 4],
        [0.5, 0.6, 2.0],
        [1.0, 2.0, 3.0],
        DMat3::IDENTITY,
    );
    let tmp = TempDir::new("frames");
    write_series(tmp.path(), &vol).unwrap();

    // A single slice: one voxel deep, k spacing from SpacingBetweenSlices.
    let one = dicom::load_file(&tmp.path().join("slice0002.dcm"), &opts()).unwrap();
    assert_eq!(one.volume.dims(), [12, 10, 1]);
    assert_eq!(one.volume.spacing(), [0.5, 0.6, 2.0]);
    assert_eq!(one.volume.data(), vol.slice_k(2));

    // An enhanced-style multi-frame file: frames stored top-down, positions per frame.
    let path = tmp.path().join("multi.dcm");
    let mut obj = open_file(tmp.path().join("slice0000.dcm")).unwrap();
    let order = [3usize, 2, 1, 0];
    let words: Vec<u16> = order
        .iter()
        .flat_map(|&k| vol.slice_k(k).iter().map(|&v| v as u16))
        .collect();
    put_pixels(&mut obj, words);
    obj.put(DataElement::new(
        tags::NUMBER_OF_FRAMES,
        VR::IS,
        PrimitiveValue::from("4"),
    ));
    let frame_groups: Vec<InMemDicomObject> = order
        .iter()
        .map(|&k| {
            let p = vol
                .geometry()
                .index_to_patient(DVec3::new(0.0, 0.0, k as f64));
            let pos = InMemDicomObject::from_element_iter([DataElement::new(
                tags::IMAGE_POSITION_PATIENT,
                VR::DS,
                PrimitiveValue::from(format!("{}\\{}\\{}", p.x, p.y, p.z)),
            )]);
            InMemDicomObject::from_element_iter([DataElement::new(
                tags::PLANE_POSITION_SEQUENCE,
                VR::SQ,
                DataSetSequence::from(vec![pos]),
            )])
        })
        .collect();
    obj.put(DataElement::new(
        tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE,
        VR::SQ,
        DataSetSequence::from(frame_groups),
    ));
    obj.remove_element(tags::IMAGE_POSITION_PATIENT);
    obj.write_to_file(&path).unwrap();
    let multi = dicom::load_file(&path, &opts()).unwrap();
    assert_same_geometry(multi.volume.geometry(), vol.geometry());
    assert!(multi.volume.data() == vol.data());

    // Without per-frame positions: stacked from the first frame along the normal.
    let mut obj = open_file(&path).unwrap();
    obj.remove_element(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE);
    put_ds(&mut obj, tags::IMAGE_POSITION_PATIENT, "1\\2\\3");
    obj.write_to_file(&path).unwrap();
    let stacked = dicom::load_file(&path, &opts()).unwrap();
    assert_eq!(stacked.volume.dims(), [12, 10, 4]);
    assert_eq!(stacked.volume.spacing(), [0.5, 0.6, 2.0]);
    assert_eq!(stacked.volume.slice_k(0), vol.slice_k(3));
    assert!(
        stacked
            .meta
            .notes
            .iter()
            .any(|n| n.contains("frames carry no positions"))
    );
}

#[test]
fn write_creates_the_folder_and_refuses_nothing_valid() {
    let vol = synthetic([4, 3, 2], [1.0; 3], [0.0; 3], DMat3::IDENTITY);
    let tmp = TempDir::new("mkdir");
    let nested = tmp.path().join("a/b/c");
    write_series(&nested, &vol).unwrap();
    assert_eq!(files_in(&nested).len(), 2);
    // No stray temporary files.
    assert!(
        files_in(&nested)
            .iter()
            .all(|p| p.extension().is_some_and(|e| e == "dcm"))
    );
}

/// Not a timed test: `cargo test --release -p voyage-io --test dicom -- --ignored --nocapture`
/// prints how long a 512×512×400 series takes to write and to load.
#[test]
#[ignore]
fn time_400_slices() {
    let g = Geometry::new([512, 512, 400], [0.7, 0.7, 1.0], [0.0; 3]).unwrap();
    let data: Vec<i16> = (0..g.len())
        .map(|i| ((i * 7919) % 3000) as i16 - 1024)
        .collect();
    let v = Volume::from_vec(g, data).unwrap();
    let tmp = TempDir::new("time400");
    let t = std::time::Instant::now();
    write_series(tmp.path(), &v).unwrap();
    println!("write 400 slices: {:?}", t.elapsed());
    for _ in 0..3 {
        let t = std::time::Instant::now();
        let l = dicom::load_dir(tmp.path(), &opts()).unwrap();
        println!("load 400 slices: {:?}", t.elapsed());
        assert!(l.volume.data() == v.data());
    }
}

/// Found by the `load_dicom` fuzzer: a fragment of encapsulated pixel data announcing 2.4 GB
/// made dicom-rs allocate it before failing. The length walk now covers the fragments.
#[test]
fn huge_fragment_length_is_refused_before_allocating() {
    let Some(data) = data_dir() else { return };
    let src = data.join("dicom/transfer-syntaxes/CTImage.dcm_JPEG2000LosslessOnlyTransferSyntax_1.2.840.10008.1.2.4.90.dcm");
    let mut bytes = std::fs::read(&src).unwrap();
    // Pixel data (7FE0,0010) OB/OW, undefined length, then the offset-table item, then fragments.
    let pd = bytes
        .windows(12)
        .position(|w| {
            w[..4] == [0xE0, 0x7F, 0x10, 0x00]
                && w[4] == b'O'
                && w[6..] == [0, 0, 0xFF, 0xFF, 0xFF, 0xFF]
        })
        .expect("encapsulated pixel data");
    let bot = pd + 12;
    assert_eq!(bytes[bot..bot + 4], [0xFE, 0xFF, 0x00, 0xE0]);
    let bot_len = u32::from_le_bytes(bytes[bot + 4..bot + 8].try_into().unwrap()) as usize;
    let frag = bot + 8 + bot_len;
    assert_eq!(bytes[frag..frag + 4], [0xFE, 0xFF, 0x00, 0xE0]);
    bytes[frag + 4..frag + 8].copy_from_slice(&0x8E4C_0000u32.to_le_bytes());
    let dir = TempDir::new("huge-fragment");
    let p = dir.path().join("huge-fragment.dcm");
    std::fs::write(&p, &bytes).unwrap();
    let err = voyage_io::load(&p, &opts()).unwrap_err().to_string();
    assert!(
        err.contains("huge-fragment.dcm") && err.contains("announces"),
        "{err}"
    );
}

/// Found by the `load_dicom` fuzzer: inside a deflated data set, an element announcing 4 GB
/// made dicom-rs allocate it while inflating. The data set is now inflated (bounded) and its
/// lengths checked before dicom-rs sees it.
#[test]
fn huge_length_inside_a_deflated_data_set_is_refused() {
    use std::io::{Read, Write};
    let Some(data) = data_dir() else { return };
    let src = data.join("dicom/transfer-syntaxes/CTImage.dcm_DeflatedExplicitVRLittleEndianTransferSyntax_1.2.840.10008.1.2.1.99.dcm");
    let bytes = std::fs::read(&src).unwrap();
    assert_eq!(&bytes[128..132], b"DICM");
    let group_len = u32::from_le_bytes(bytes[140..144].try_into().unwrap()) as usize;
    let meta_end = 144 + group_len;
    let mut inflated = Vec::new();
    flate2::read::DeflateDecoder::new(&bytes[meta_end..])
        .read_to_end(&mut inflated)
        .unwrap();
    // A private element announcing 4 GB, in front of the real data set.
    let mut bomb = vec![0x09, 0x00, 0x10, 0x00, b'U', b'N', 0, 0];
    bomb.extend_from_slice(&0xF000_0000u32.to_le_bytes());
    bomb.extend_from_slice(&inflated);
    let mut enc = flate2::write::DeflateEncoder::new(Vec::new(), flate2::Compression::default());
    enc.write_all(&bomb).unwrap();
    let mut file = bytes[..meta_end].to_vec();
    file.extend_from_slice(&enc.finish().unwrap());
    let dir = TempDir::new("deflate-bomb");
    let p = dir.path().join("deflate-bomb.dcm");
    std::fs::write(&p, &file).unwrap();
    let err = voyage_io::load(&p, &opts()).unwrap_err().to_string();
    assert!(
        err.contains("deflate-bomb.dcm") && err.contains("announces"),
        "{err}"
    );
}

/// Found by the `load_dicom` fuzzer (kept in `fuzz/finds`), each made dicom-rs reserve 3.5–4.3 GB
/// before failing:
/// - a sequence delimiter (FFFE,E0DD) declaring 4.28 GB, where a delimiter's length should be
///   0 (dicom-rs reads it as a value); the length walk now bounds delimiters too;
/// - an unknown (FFFE,E02D) inside a sequence, which the walk took for a delimiter and dicom-rs
///   for a plain element, so dicom-rs was still inside the sequence at the pixel data, which
///   declares 3.55 GB. The walk now reads (FFFE,xxxx) as dicom-rs does, and the header read is
///   given only the bytes before the pixel data.
#[test]
fn huge_lengths_the_fuzzer_found_are_refused_before_allocating() {
    let finds: [(&str, &[u8], &str); 4] = [
        (
            "huge-delimiter.dcm",
            include_bytes!("../../../fuzz/finds/load_dicom-oom-element-length.dcm"),
            "(FFFE,E0DD) announces 4278190080",
        ),
        (
            "unknown-item-tag.dcm",
            include_bytes!("../../../fuzz/finds/load_dicom-oom-unknown-item-tag.dcm"),
            "(7FE0,0010) announces 3553874689",
        ),
        // The walk cannot see this one (a defined-length sequence its item overruns): the
        // bound on what dicom-rs may allocate for the file refuses the 4.27 GB.
        (
            "overrun-sequence.dcm",
            include_bytes!("../../../fuzz/finds/load_dicom-oom-overrun-sequence.dcm"),
            "not a readable DICOM file",
        ),
        // Below the bound: dicom-rs allocates 766 MB where a refusal would abort the process,
        // and fails into an error, as before the bound.
        (
            "766mb-then-error.dcm",
            include_bytes!("../../../fuzz/finds/load_dicom-766mb-then-error.dcm"),
            "not a readable DICOM file",
        ),
    ];
    let dir = TempDir::new("fuzz-finds");
    for (name, bytes, says) in finds {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        let err = voyage_io::load(&p, &opts()).unwrap_err().to_string();
        assert!(err.contains(name) && err.contains(says), "{err}");
    }
}

/// Writes a 4×4 CT slice whose RLE segments decode to one byte each instead of sixteen: the
/// shape of a file the `load_dicom` fuzzer found to panic inside dicom-rs's RLE decoder.
pub fn short_rle_file(path: &Path) {
    use dicom_core::value::PixelFragmentSequence;
    let g = Geometry::new([4, 4, 1], [0.7, 0.7, 1.0], [0.0; 3]).unwrap();
    let dir = path.parent().unwrap().join("rle-src");
    write_series(&dir, &Volume::filled(g, 7i16).unwrap()).unwrap();
    let src = files_in(&dir).remove(0);
    let mut obj = open_file(&src).unwrap();
    obj.meta_mut().transfer_syntax = "1.2.840.10008.1.2.5".to_string();
    let mut frame = vec![0u8; 64];
    frame[0..4].copy_from_slice(&2u32.to_le_bytes());
    frame[4..8].copy_from_slice(&64u32.to_le_bytes());
    frame[8..12].copy_from_slice(&66u32.to_le_bytes());
    frame.extend_from_slice(&[0x00, 0x01, 0x00, 0x02]);
    let pixels = PixelFragmentSequence::new(Vec::<u32>::new(), vec![frame]);
    obj.put(DataElement::new(tags::PIXEL_DATA, VR::OB, pixels));
    obj.write_to_file(path).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn short_rle_segments_give_an_error_not_a_panic() {
    let dir = TempDir::new("short-rle");
    let p = dir.path().join("short-rle.dcm");
    short_rle_file(&p);
    let err = voyage_io::load(&p, &opts()).unwrap_err().to_string();
    assert!(
        err.contains("short-rle.dcm") && err.contains("RLE"),
        "{err}"
    );
    assert_eq!(err.lines().count(), 1, "{err}");
}

/// A colour dose screen in another series (a secondary capture) is skipped and said, not a
/// reason to refuse the folder; asked for by its series, it is refused with its reason.
#[test]
fn an_unloadable_image_of_another_series_does_not_refuse_the_folder() {
    let vol = synthetic([16, 16, 6], [1.0; 3], [0.0; 3], DMat3::IDENTITY);
    let tmp = TempDir::new("dosescreen");
    write_series(tmp.path(), &vol).unwrap();
    let screen = tmp.path().join("dose.dcm");
    std::fs::copy(tmp.path().join("slice0000.dcm"), &screen).unwrap();
    edit_file(&screen, |o| {
        put_us(o, tags::SAMPLES_PER_PIXEL, 3);
        o.put(DataElement::new(
            tags::PHOTOMETRIC_INTERPRETATION,
            VR::CS,
            PrimitiveValue::from("RGB"),
        ));
        o.put(DataElement::new(
            tags::SERIES_INSTANCE_UID,
            VR::UI,
            PrimitiveValue::from("1.2.3.99"),
        ));
    });
    let l = dicom::load_dir(tmp.path(), &opts()).unwrap();
    assert!(l.volume.data() == vol.data());
    assert!(
        l.meta.notes.iter().any(|n| n.contains("1.2.3.99")
            && n.contains("dose.dcm")
            && n.contains("not a grayscale image")),
        "{:?}",
        l.meta.notes
    );
    let want = LoadOptions {
        series_uid: Some("1.2.3.99".into()),
    };
    let msg = err_text(dicom::load_dir(tmp.path(), &want));
    assert!(
        msg.contains("dose.dcm") && msg.contains("not a grayscale image"),
        "{msg}"
    );
}

/// A slice left gzip-compressed (`.dcm.gz`) is named: in the note when the rest loads, and
/// in the error when it leaves a slice missing.
#[test]
fn gzipped_slices_are_named() {
    use std::io::Write;
    let vol = synthetic([16, 16, 6], [1.0; 3], [0.0; 3], DMat3::IDENTITY);
    let tmp = TempDir::new("gzipped");
    write_series(tmp.path(), &vol).unwrap();
    let gzip = |name: &str, to: &str| {
        let bytes = std::fs::read(tmp.path().join(name)).unwrap();
        let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        e.write_all(&bytes).unwrap();
        std::fs::write(tmp.path().join(to), e.finish().unwrap()).unwrap();
    };
    // A compressed copy beside the plain slices: the series loads, and the copy is named.
    gzip("slice0002.dcm", "copy.dcm.gz");
    let l = dicom::load_dir(tmp.path(), &opts()).unwrap();
    assert!(
        l.meta
            .notes
            .iter()
            .any(|n| n.contains("copy.dcm.gz") && n.contains("gzip")),
        "{:?}",
        l.meta.notes
    );
    // A slice only compressed: the gap it leaves names it.
    gzip("slice0003.dcm", "slice0003.dcm.gz");
    std::fs::remove_file(tmp.path().join("slice0003.dcm")).unwrap();
    let msg = err_text(dicom::load_dir(tmp.path(), &opts()));
    assert!(
        msg.contains("missing") && msg.contains("slice0003.dcm.gz") && msg.contains("gzip"),
        "{msg}"
    );
}
