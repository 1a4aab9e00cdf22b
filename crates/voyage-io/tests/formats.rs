//! Loaders and writers for NIfTI-1, MetaImage and NRRD: round trips, real files from
//! `../shared/data`, hand-made headers in other byte orders and spaces, and bad input
//! (every error names the file; nothing panics; nothing huge is allocated).

use std::{
    io::Write,
    path::{Path, PathBuf},
    sync::atomic::{AtomicUsize, Ordering},
};

use voyage_core::{Geometry, Volume};
use voyage_io::{self as io, Format, LoadOptions, Loaded, metaimage, nifti, nrrd};

// ---------------------------------------------------------------------------------------
// Helpers

/// A writer under test.
type Saver = fn(&Path, &Volume<i16>) -> voyage_core::Result<()>;

/// A unique temporary folder, removed on drop.
struct TempDir(PathBuf);

impl TempDir {
    fn new(tag: &str) -> TempDir {
        static COUNTER: AtomicUsize = AtomicUsize::new(0);
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let dir =
            std::env::temp_dir().join(format!("voyage-formats-{tag}-{}-{n}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        TempDir(dir)
    }
    fn join(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// i → P, j → R, k → I: a 90° turn about z with a flipped k axis (left-handed).
const TURNED_FLIPPED: [[f64; 3]; 3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]];

/// 37×23×11, anisotropic, off-origin, with values that span negative and > 255 HU.
fn synthetic(direction: [[f64; 3]; 3]) -> Volume<i16> {
    let mut g = Geometry::new([37, 23, 11], [0.82, 0.82, 1.25], [-12.5, 30.25, 100.75]).unwrap();
    g.direction = direction;
    let data = (0..g.len())
        .map(|idx| {
            let [i, j, k] = g.ijk(idx);
            (i as i16) * 7 + (j as i16) * 13 + (k as i16) * 101 - 1000
        })
        .collect();
    Volume::from_vec(g, data).unwrap()
}

/// A proper rotation that is not axis-aligned (30° about x, then 20° about z).
fn oblique() -> [[f64; 3]; 3] {
    let m = glam::DMat3::from_rotation_z(20f64.to_radians())
        * glam::DMat3::from_rotation_x(30f64.to_radians());
    let mut g = Geometry::new([1, 1, 1], [1.0; 3], [0.0; 3]).unwrap();
    g.set_direction_mat(m);
    g.direction
}

fn assert_geometry_close(a: &Geometry, b: &Geometry) {
    assert_eq!(a.dims, b.dims);
    let close = |x: &[f64], y: &[f64]| x.iter().zip(y).all(|(p, q)| (p - q).abs() < 1e-5);
    assert!(
        close(&a.spacing, &b.spacing),
        "spacing {:?} vs {:?}",
        a.spacing,
        b.spacing
    );
    assert!(
        close(&a.origin, &b.origin),
        "origin {:?} vs {:?}",
        a.origin,
        b.origin
    );
    for r in 0..3 {
        assert!(
            close(&a.direction[r], &b.direction[r]),
            "direction {:?} vs {:?}",
            a.direction,
            b.direction
        );
    }
}

fn assert_same(loaded: &Loaded, expected: &Volume<i16>) {
    assert_geometry_close(loaded.volume.geometry(), expected.geometry());
    assert!(loaded.volume.data() == expected.data(), "voxels differ");
}

fn load_any(path: &Path) -> voyage_core::Result<Loaded> {
    io::load(path, &LoadOptions::default())
}

/// Loading must fail, and the one-line message must name the file.
fn assert_err_names(path: &Path, expect_in_msg: &str) -> String {
    let err = match load_any(path) {
        Ok(_) => panic!("{} loaded but should not", path.display()),
        Err(e) => e.to_string(),
    };
    let name = path.file_name().unwrap().to_string_lossy();
    assert!(
        err.contains(name.as_ref()),
        "message does not name {name}: {err}"
    );
    assert!(
        err.contains(expect_in_msg),
        "message lacks \"{expect_in_msg}\": {err}"
    );
    assert!(!err.contains('\n'), "message is not one line: {err}");
    err
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    e.write_all(bytes).unwrap();
    e.finish().unwrap()
}

fn gunzip(bytes: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    std::io::Read::read_to_end(&mut flate2::read::MultiGzDecoder::new(bytes), &mut out).unwrap();
    out
}

/// A bare NIfTI-1 header (no sform/qform) in either byte order, for hand-made files.
struct NiftiHeader {
    big: bool,
    dim: [i16; 8],
    datatype: i16,
    bitpix: i16,
    pixdim: [f32; 8],
    slope: f32,
    inter: f32,
}

impl NiftiHeader {
    fn new(dims: [i16; 3], datatype: i16, bitpix: i16) -> Self {
        NiftiHeader {
            big: false,
            dim: [3, dims[0], dims[1], dims[2], 1, 1, 1, 1],
            datatype,
            bitpix,
            pixdim: [1.0, 0.5, 0.75, 2.0, 1.0, 1.0, 1.0, 1.0],
            slope: 0.0,
            inter: 0.0,
        }
    }
    fn bytes(&self) -> Vec<u8> {
        let mut h = vec![0u8; 352];
        let big = self.big;
        let mut put = |off: usize, b: &[u8]| {
            let mut b = b.to_vec();
            if big {
                b.reverse();
            }
            h[off..off + b.len()].copy_from_slice(&b);
        };
        put(0, &348i32.to_le_bytes());
        for (i, d) in self.dim.iter().enumerate() {
            put(40 + 2 * i, &d.to_le_bytes());
        }
        put(70, &self.datatype.to_le_bytes());
        put(72, &self.bitpix.to_le_bytes());
        for (i, p) in self.pixdim.iter().enumerate() {
            put(76 + 4 * i, &p.to_le_bytes());
        }
        put(108, &352f32.to_le_bytes());
        put(112, &self.slope.to_le_bytes());
        put(116, &self.inter.to_le_bytes());
        h[344..348].copy_from_slice(b"n+1\0");
        h
    }
}

use voyage_phantom::fixtures::shared_data;

// ---------------------------------------------------------------------------------------
// Round trips

#[test]
fn nifti_round_trip_nii_and_gz() {
    let dir = TempDir::new("nifti-rt");
    for direction in [TURNED_FLIPPED, oblique()] {
        let vol = synthetic(direction);
        for name in ["a.nii", "a.nii.gz"] {
            let p = dir.join(name);
            nifti::save(&p, &vol).unwrap();
            let loaded = nifti::load(&p).unwrap();
            assert_same(&loaded, &vol);
            assert_eq!(loaded.meta.format, Some(Format::Nifti));
            assert_eq!(loaded.meta.files, 1);
        }
        assert_eq!(
            &std::fs::read(dir.join("a.nii.gz")).unwrap()[..2],
            &[0x1f, 0x8b],
            "not gzip"
        );
        assert_eq!(
            std::fs::read(dir.join("a.nii")).unwrap().len(),
            352 + 2 * vol.data().len()
        );
    }
    nifti::save_i16(&dir.join("b.nii"), &synthetic(TURNED_FLIPPED)).unwrap();
    assert_same(
        &nifti::load(&dir.join("b.nii")).unwrap(),
        &synthetic(TURNED_FLIPPED),
    );
}

/// The qform we write agrees with the sform: load once with the sform turned off.
#[test]
fn nifti_qform_and_no_transform() {
    let dir = TempDir::new("nifti-qform");
    for direction in [TURNED_FLIPPED, oblique(), voyage_core::IDENTITY] {
        let vol = synthetic(direction);
        let p = dir.join("q.nii");
        nifti::save(&p, &vol).unwrap();
        let mut bytes = std::fs::read(&p).unwrap();
        bytes[254..256].copy_from_slice(&0i16.to_le_bytes()); // sform_code = 0
        std::fs::write(&p, &bytes).unwrap();
        let loaded = nifti::load(&p).unwrap();
        assert_same(&loaded, &vol);
        assert!(
            loaded.meta.notes.iter().any(|n| n.contains("qform")),
            "{:?}",
            loaded.meta.notes
        );

        bytes[252..254].copy_from_slice(&0i16.to_le_bytes()); // qform_code = 0 too
        std::fs::write(&p, &bytes).unwrap();
        let g = nifti::load(&p).unwrap().volume.geometry().clone();
        assert_eq!(g.origin, [0.0; 3]);
        assert_eq!(
            g.orientation_code(),
            "RAS",
            "pixdim only: voxel axes are RAS"
        );
        assert!((g.spacing[2] - 1.25).abs() < 1e-6);
    }
}

#[test]
fn nifti_u8_mask_and_f32_round_trip() {
    let dir = TempDir::new("nifti-types");
    let vol = synthetic(TURNED_FLIPPED);
    let mask = vol.map(|v| u8::from(v > -500));
    let p = dir.join("mask.nii.gz");
    nifti::save(&p, &mask).unwrap();
    let loaded = nifti::load(&p).unwrap();
    assert_same(&loaded, &mask.map(i16::from));
    assert_eq!(
        std::fs::read(&p).map(|b| gunzip(&b)[70]).unwrap(),
        2,
        "datatype u8"
    );

    let mut f = vol.map(|v| f32::from(v) + 0.4);
    f.data_mut()[0] = f32::NAN;
    f.data_mut()[1] = 1e9;
    f.data_mut()[2] = -2.5;
    let p = dir.join("float.nii");
    nifti::save(&p, &f).unwrap();
    let loaded = nifti::load(&p).unwrap();
    let mut expected = vol.clone();
    expected.data_mut()[0] = -1024;
    expected.data_mut()[1] = i16::MAX;
    expected.data_mut()[2] = -3; // rounds half away from zero
    assert_same(&loaded, &expected);
    let notes = loaded.meta.notes.join("; ");
    assert!(
        notes.contains("1 NaN voxels set to -1024") && notes.contains("1 voxels outside"),
        "{notes}"
    );

    let p = dir.join("u16.nii");
    let u = vol.map(|v| (v + 1000) as u16);
    nifti::save(&p, &u).unwrap();
    assert_same(&nifti::load(&p).unwrap(), &u.map(|x| x as i16));
    let p = dir.join("i32b.nii");
    nifti::save(&p, &vol.map(i32::from)).unwrap();
    assert_same(&nifti::load(&p).unwrap(), &vol);
}

/// A big-endian u16 file with slope/intercept, written by hand.
#[test]
fn nifti_big_endian_with_rescale() {
    let dir = TempDir::new("nifti-be");
    let mut h = NiftiHeader::new([2, 2, 1], 512, 16);
    h.big = true;
    h.slope = 1.0;
    h.inter = -1024.0;
    let mut bytes = h.bytes();
    for v in [0u16, 1000, 2048, 65535] {
        bytes.extend_from_slice(&v.to_be_bytes());
    }
    let p = dir.join("be.nii");
    std::fs::write(&p, &bytes).unwrap();
    let loaded = nifti::load(&p).unwrap();
    assert_eq!(loaded.volume.data(), &[-1024, -24, 1024, i16::MAX]);
    assert_eq!(loaded.volume.spacing(), [0.5, 0.75, 2.0]);
    assert!(
        loaded
            .meta
            .notes
            .iter()
            .any(|n| n.contains("1 voxels outside the i16 range"))
    );

    // The same values as little-endian f64 with slope 2: 4D with a unit 4th axis.
    let mut h = NiftiHeader::new([2, 2, 1], 64, 64);
    h.dim[0] = 4;
    h.slope = 2.0;
    let mut bytes = h.bytes();
    for v in [-500.25f64, 0.0, 1.0, 10.0] {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    std::fs::write(&p, gzip(&bytes)).unwrap();
    assert_eq!(nifti::load(&p).unwrap().volume.data(), &[-1001, 0, 2, 20]);
}

#[test]
fn metaimage_round_trip_mha_and_mhd() {
    let dir = TempDir::new("mha-rt");
    for direction in [TURNED_FLIPPED, oblique()] {
        let vol = synthetic(direction);
        for name in ["a.mha", "a.mhd"] {
            let p = dir.join(name);
            metaimage::save(&p, &vol).unwrap();
            let loaded = metaimage::load(&p).unwrap();
            assert_same(&loaded, &vol);
            assert_eq!(loaded.meta.format, Some(Format::MetaImage));
        }
        assert_eq!(metaimage::load(&dir.join("a.mhd")).unwrap().meta.files, 2);
        assert!(dir.join("a.raw").exists());
    }
}

/// ITK's TransformMatrix lists the axis directions one after the other (the columns).
#[test]
fn metaimage_hand_written_conventions() {
    let dir = TempDir::new("mha-hand");
    let header = "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = True\n\
                  TransformMatrix = 0 1 0 -1 0 0 0 0 1\nOffset = 1 2 3\nElementSpacing = 0.5 0.6 2\n\
                  DimSize = 2 2 1\nElementType = MET_USHORT\nHeaderSize = 4\nModality = MET_MOD_CT\n\
                  ElementDataFile = data/voxels.bin\n";
    std::fs::create_dir_all(dir.join("data")).unwrap();
    std::fs::write(dir.join("h.mhd"), header).unwrap();
    let mut raw = vec![9u8; 4];
    for v in [1u16, 2, 300, 40000] {
        raw.extend_from_slice(&v.to_be_bytes());
    }
    std::fs::write(dir.join("data/voxels.bin"), &raw).unwrap();
    let loaded = load_any(&dir.join("h.mhd")).unwrap();
    let g = loaded.volume.geometry();
    assert_eq!(loaded.volume.data(), &[1, 2, 300, i16::MAX]);
    assert_eq!(
        g.direction,
        [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
        "i axis is (0,1,0)"
    );
    assert_eq!(g.orientation_code(), "PRS");
    assert_eq!((g.origin, g.spacing), ([1.0, 2.0, 3.0], [0.5, 0.6, 2.0]));
    assert_eq!(loaded.meta.modality.as_deref(), Some("CT"));

    // Inline gzip data (which MetaIO also accepts), no CompressedDataSize, MET_FLOAT.
    let mut mha = b"NDims = 3\nDimSize = 3 1 1\nElementType = MET_FLOAT\nCompressedData = True\n\
                    ElementDataFile = LOCAL\n"
        .to_vec();
    let floats: Vec<u8> = [-1000.0f32, 0.49, 70.5]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    mha.extend(gzip(&floats));
    std::fs::write(dir.join("f.mha"), &mha).unwrap();
    let loaded = load_any(&dir.join("f.mha")).unwrap();
    assert_eq!(loaded.volume.data(), &[-1000, 0, 71]);
    assert_eq!(loaded.volume.spacing(), [1.0; 3]);
}

#[test]
fn nrrd_round_trip_nrrd_and_nhdr() {
    let dir = TempDir::new("nrrd-rt");
    for direction in [TURNED_FLIPPED, oblique()] {
        let vol = synthetic(direction);
        for name in ["a.nrrd", "a.nhdr"] {
            let p = dir.join(name);
            nrrd::save(&p, &vol).unwrap();
            let loaded = nrrd::load(&p).unwrap();
            assert_same(&loaded, &vol);
            assert_eq!(loaded.meta.format, Some(Format::Nrrd));
        }
        assert!(dir.join("a.raw.gz").exists());
        assert_eq!(nrrd::load(&dir.join("a.nhdr")).unwrap().meta.files, 2);
    }
}

/// RAS space is converted to LPS; raw big-endian data with a line skip and byte skip.
#[test]
fn nrrd_hand_written_ras_raw() {
    let dir = TempDir::new("nrrd-hand");
    let mut bytes = b"NRRD0005\n# a comment\ntype: int16\ndimension: 3\nspace: right-anterior-superior\n\
                      sizes: 2 1 2\nspace directions: (-0.5, 0,0) (0,-0.5,0) (0,0,2)\nkinds: domain domain domain\n\
                      endian: big\nencoding: raw\nspace origin: (10,20,30)\nmy key:=my value\nbyte skip: 3\n\n"
        .to_vec();
    bytes.extend_from_slice(b"xyz");
    for v in [-1000i16, 5, 300, -2] {
        bytes.extend_from_slice(&v.to_be_bytes());
    }
    let p = dir.join("ras.nrrd");
    std::fs::write(&p, &bytes).unwrap();
    let loaded = load_any(&p).unwrap();
    let g = loaded.volume.geometry();
    assert_eq!(loaded.volume.data(), &[-1000, 5, 300, -2]);
    assert_eq!(g.spacing, [0.5, 0.5, 2.0]);
    assert_eq!(g.origin, [-10.0, -20.0, 30.0]);
    assert_eq!(g.orientation_code(), "LPS");

    // Detached gzip data with spacings only, u8, after one skipped line.
    std::fs::write(
        dir.join("d.nhdr"),
        "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 3 1 1\nspacings: 0.7 0.8 0.9\nencoding: gz\n\
         line skip: 1\ndata file: d.bin\n",
    )
    .unwrap();
    let mut data = b"junk line\n".to_vec();
    data.extend(gzip(&[0, 1, 255]));
    std::fs::write(dir.join("d.bin"), data).unwrap();
    let loaded = load_any(&dir.join("d.nhdr")).unwrap();
    assert_eq!(loaded.volume.data(), &[0, 1, 255]);
    assert_eq!(loaded.volume.spacing(), [0.7, 0.8, 0.9]);
}

#[test]
fn load_dispatches_by_extension() {
    let dir = TempDir::new("dispatch");
    let vol = synthetic(TURNED_FLIPPED);
    let cases: [(&str, Format, Saver); 6] = [
        ("v.nii", Format::Nifti, nifti::save_i16),
        ("v.nii.gz", Format::Nifti, nifti::save_i16),
        ("v.mha", Format::MetaImage, metaimage::save),
        ("v.mhd", Format::MetaImage, metaimage::save),
        ("v.nrrd", Format::Nrrd, nrrd::save),
        ("v.nhdr", Format::Nrrd, nrrd::save),
    ];
    for (name, format, save) in cases {
        let p = dir.join(name);
        save(&p, &vol).unwrap();
        assert_eq!(io::detect_format(&p).unwrap(), format);
        let loaded = load_any(&p).unwrap();
        assert_eq!(loaded.meta.format, Some(format), "{name}");
        assert_same(&loaded, &vol);
    }
}

// ---------------------------------------------------------------------------------------
// Real files

#[test]
fn real_abdomen_ct() {
    let Some(data) = shared_data() else { return };
    let loaded = load_any(&data.join("ct/abdomen-3mm.nii.gz")).unwrap();
    let v = &loaded.volume;
    let g = v.geometry();
    assert_eq!(g.dims, [122, 101, 112]);
    assert_eq!(g.spacing, [3.0; 3]);
    // Stored as int32 with sform code 2 = diag(3, 3, 3) in RAS: the voxel axes run to
    // R, A, S, so in LPS the direction is diag(-1, -1, 1) and x, y of the origin flip.
    assert_eq!(v.min_max(), (-1207, 3382));
    assert_eq!(g.orientation_code(), "RAS");
    assert_eq!(
        g.direction,
        [[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]]
    );
    let expected_origin = [177.95632934570312, -11.319000244140625, 94.3017578125];
    assert!(
        g.origin
            .iter()
            .zip(expected_origin)
            .all(|(a, b)| (a - b).abs() < 1e-4),
        "{:?}",
        g.origin
    );
    assert_eq!(loaded.meta.format, Some(Format::Nifti));
}

#[test]
fn real_abdomen_colon_mask() {
    let Some(data) = shared_data() else { return };
    let ct = load_any(&data.join("ct/abdomen-3mm.nii.gz")).unwrap();
    let mask = load_any(&data.join("ct/abdomen-3mm-colon.nii.gz")).unwrap();
    assert_geometry_close(mask.volume.geometry(), ct.volume.geometry());
    // Stored as float64 0.0/1.0.
    assert!(mask.volume.data().iter().all(|&v| v == 0 || v == 1));
    assert_eq!(
        mask.volume.data().iter().filter(|&&v| v == 1).count(),
        57_888
    );
}

#[test]
fn real_colon_a_mask() {
    let Some(data) = shared_data() else { return };
    let path = data.join("masks/colon-a.nii.gz");
    let loaded = load_any(&path).unwrap();
    let v = &loaded.volume;
    let g = v.geometry();
    assert_eq!(g.dims, [512, 512, 321]);
    assert!(
        (g.spacing[0] - 0.820312).abs() < 1e-5 && (g.spacing[1] - 0.820312).abs() < 1e-5,
        "{:?}",
        g.spacing
    );
    assert_eq!(g.spacing[2], 1.25);
    // uint16, sform code 1 = diag(-0.82, -0.82, 1.25) in RAS: axes run L, P, S, so the
    // LPS direction is the identity; the origin's x and y flip sign.
    assert_eq!(g.orientation_code(), "LPS");
    assert_eq!(g.direction, voyage_core::IDENTITY);
    let expected_origin = [-210.0, -229.9, -469.28];
    assert!(
        g.origin
            .iter()
            .zip(expected_origin)
            .all(|(a, b)| (a - b).abs() < 1e-4),
        "{:?}",
        g.origin
    );
    assert!(v.data().iter().all(|&x| x == 0 || x == 1));
    assert_eq!(v.data().iter().filter(|&&x| x == 1).count(), 4_546_993);

    // Its qform (code 2, quaternion (0,0,1): 180° about z) gives the same geometry.
    let dir = TempDir::new("colon-qform");
    let mut raw = gunzip(&std::fs::read(&path).unwrap());
    raw[254..256].copy_from_slice(&0i16.to_le_bytes());
    let p = dir.join("colon-qform.nii");
    std::fs::write(&p, &raw).unwrap();
    let q = load_any(&p).unwrap();
    assert_geometry_close(q.volume.geometry(), g);
    assert!(q.volume.data() == v.data());
}

// ---------------------------------------------------------------------------------------
// Bad input

#[test]
fn truncated_files_are_refused() {
    let dir = TempDir::new("truncated");
    let vol = synthetic(TURNED_FLIPPED);
    let p = dir.join("whole.nii.gz");
    nifti::save(&p, &vol).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    let half = dir.join("half.nii.gz");
    std::fs::write(&half, &bytes[..bytes.len() / 2]).unwrap();
    assert_err_names(
        &half,
        "truncated: expected 18722 bytes of voxel data, found",
    );

    let tail = dir.join("no-crc.nii.gz");
    std::fs::write(&tail, &bytes[..bytes.len() - 4]).unwrap();
    assert_err_names(&tail, "ends before its checksum");

    let p = dir.join("whole.nii");
    nifti::save(&p, &vol).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    let cut = dir.join("cut.nii");
    std::fs::write(&cut, &bytes[..1000]).unwrap();
    assert_err_names(
        &cut,
        "truncated: expected 18722 bytes of voxel data, found 648",
    );
    std::fs::write(&cut, &bytes[..200]).unwrap();
    assert_err_names(&cut, "too short for a NIfTI-1 header");

    for (name, save) in [("t.mha", metaimage::save as Saver), ("t.nrrd", nrrd::save)] {
        let p = dir.join(name);
        save(&p, &vol).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..bytes.len() - 300]).unwrap();
        assert_err_names(&p, "truncated");
    }
    let p = dir.join("t.mhd");
    metaimage::save(&p, &vol).unwrap();
    let raw = dir.join("t.raw");
    let bytes = std::fs::read(&raw).unwrap();
    std::fs::write(&raw, &bytes[..100]).unwrap();
    assert_err_names(&p, "truncated");
}

#[test]
fn real_file_cut_in_half() {
    let Some(data) = shared_data() else { return };
    let dir = TempDir::new("real-cut");
    let bytes = std::fs::read(data.join("ct/abdomen-3mm.nii.gz")).unwrap();
    let p = dir.join("abdomen-half.nii.gz");
    std::fs::write(&p, &bytes[..bytes.len() / 2]).unwrap();
    assert_err_names(&p, "truncated: expected 5520256 bytes of voxel data, found");
}

/// Headers that promise absurd sizes fail at once, before any large allocation.
#[test]
fn huge_or_bad_dims_fail_fast() {
    let dir = TempDir::new("huge");
    let p = dir.join("huge.nii");
    // NIfTI-1 dims are 16-bit: 32767³ is the largest it can say.
    std::fs::write(&p, NiftiHeader::new([32767, 32767, 32767], 4, 16).bytes()).unwrap();
    assert_err_names(&p, "voxels, over the limit");
    // 1000³ i16 is within the voxel limit but the file holds no data: refused before
    // allocating 2 GB.
    std::fs::write(&p, NiftiHeader::new([1000, 1000, 1000], 4, 16).bytes()).unwrap();
    let start = std::time::Instant::now();
    assert_err_names(
        &p,
        "truncated: expected 2000000000 bytes of voxel data, found 0",
    );
    let gz = dir.join("huge.nii.gz");
    std::fs::write(
        &gz,
        gzip(&NiftiHeader::new([1000, 1000, 1000], 4, 16).bytes()),
    )
    .unwrap();
    assert_err_names(&gz, "the compressed file can hold at most");
    assert!(start.elapsed().as_secs() < 5);

    std::fs::write(&p, NiftiHeader::new([-5, 2, 2], 4, 16).bytes()).unwrap();
    assert_err_names(&p, "must all be at least 1");
    let mut h = NiftiHeader::new([2, 2, 2], 4, 16);
    h.dim = [4, 2, 2, 2, 3, 1, 1, 1];
    std::fs::write(&p, h.bytes()).unwrap();
    assert_err_names(&p, "is not a single 3D volume");
    let mut h = NiftiHeader::new([2, 2, 2], 4, 16);
    h.pixdim[2] = 0.0;
    std::fs::write(&p, [h.bytes(), vec![0; 16]].concat()).unwrap();
    assert_err_names(&p, "voxel sizes must be positive and finite");
    h.pixdim[2] = f32::NAN;
    std::fs::write(&p, [h.bytes(), vec![0; 16]].concat()).unwrap();
    assert_err_names(&p, "voxel sizes must be positive and finite");
    // Sizes no scan has: every length measured, and the centerline's resampling, would be
    // out of all proportion (1e30 mm grew memory past 20 GB).
    for size in [1e30, 1e-4] {
        h.pixdim[2] = size;
        std::fs::write(&p, [h.bytes(), vec![0; 16]].concat()).unwrap();
        assert_err_names(&p, "lies outside 0.01–50 mm");
    }
    // A rescale out of all proportion: every voxel saturates.
    let mut h = NiftiHeader::new([2, 2, 2], 4, 16);
    h.slope = 1e30;
    std::fs::write(&p, [h.bytes(), vec![1; 16]].concat()).unwrap();
    assert_err_names(&p, "are not CT numbers");
    let h = NiftiHeader::new([2, 2, 2], 128, 24);
    std::fs::write(&p, [h.bytes(), vec![0; 24]].concat()).unwrap();
    assert_err_names(&p, "datatype 128 is not supported");

    let mhd = dir.join("huge.mha");
    std::fs::write(&mhd, "NDims = 3\nDimSize = 60000 60000 60000\nElementType = MET_SHORT\nElementDataFile = LOCAL\n")
        .unwrap();
    assert_err_names(&mhd, "over the limit");
    std::fs::write(
        &mhd,
        "NDims = 3\nDimSize = 2 2 2\nElementSpacing = 1 1e30 1\nElementType = MET_SHORT\nElementDataFile = LOCAL\n",
    )
    .unwrap();
    std::fs::write(&mhd, [std::fs::read(&mhd).unwrap(), vec![0; 16]].concat()).unwrap();
    assert_err_names(&mhd, "lies outside 0.01–50 mm");
    let nrrd = dir.join("huge.nrrd");
    std::fs::write(
        &nrrd,
        "NRRD0004\ntype: short\ndimension: 3\nsizes: 1000 1000 1000\nencoding: raw\n\n",
    )
    .unwrap();
    assert_err_names(&nrrd, "truncated");
}

#[test]
fn sheared_sform_is_refused() {
    let dir = TempDir::new("shear");
    let p = dir.join("shear.nii");
    nifti::save(&p, &synthetic(voyage_core::IDENTITY)).unwrap();
    let mut bytes = std::fs::read(&p).unwrap();
    bytes[284..288].copy_from_slice(&0.3f32.to_le_bytes()); // srow_x[1]: j leans into x
    bytes[252..254].copy_from_slice(&0i16.to_le_bytes()); // no qform to fall back on
    std::fs::write(&p, &bytes).unwrap();
    assert_err_names(&p, "not perpendicular");
    bytes[252..254].copy_from_slice(&1i16.to_le_bytes()); // with a qform: fall back
    std::fs::write(&p, &bytes).unwrap();
    let loaded = nifti::load(&p).unwrap();
    assert!(
        loaded
            .meta
            .notes
            .iter()
            .any(|n| n.contains("sform ignored")),
        "{:?}",
        loaded.meta.notes
    );
}

#[test]
fn garbage_empty_and_missing_files() {
    let dir = TempDir::new("garbage");
    let mut seed = 12345u64;
    let garbage: Vec<u8> = (0..4000)
        .map(|_| {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 56) as u8
        })
        .collect();
    for (name, msg) in [
        ("junk.nii", "not a NIfTI-1 file"),
        ("junk.mha", "MetaImage"),
        ("junk.nrrd", "not a NRRD file"),
    ] {
        let p = dir.join(name);
        std::fs::write(&p, &garbage).unwrap();
        assert_err_names(&p, msg);
    }
    for name in ["empty.nii", "empty.nii.gz", "empty.mha", "empty.nrrd"] {
        let p = dir.join(name);
        std::fs::write(&p, b"").unwrap();
        assert_err_names(&p, "empty file");
    }
    // Compressed files damaged in the middle: refused (by the CRC or the inflater), even
    // when the damaged stream still inflates to the right length.
    for (name, save) in [
        ("damaged.nii.gz", nifti::save_i16 as Saver),
        ("damaged.mha", metaimage::save),
        ("damaged.nrrd", nrrd::save),
    ] {
        let p = dir.join(name);
        save(&p, &synthetic(TURNED_FLIPPED)).unwrap();
        let original = std::fs::read(&p).unwrap();
        for (at, len, fill) in [(2, 40, 0xff), (3, 1, 0x00), (5, 8, 0x55)] {
            let mut bytes = original.clone();
            let start = bytes.len() * at / 7;
            bytes[start..start + len].fill(fill);
            std::fs::write(&p, &bytes).unwrap();
            let err = load_any(&p).expect_err(name).to_string();
            assert!(err.contains(name), "{err}");
        }
    }

    let mhd = dir.join("orphan.mhd");
    std::fs::write(
        &mhd,
        "NDims = 3\nDimSize = 2 2 2\nElementType = MET_SHORT\nElementDataFile = orphan.raw\n",
    )
    .unwrap();
    assert_err_names(&mhd, "orphan.raw");
    let nhdr = dir.join("orphan.nhdr");
    std::fs::write(
        &nhdr,
        "NRRD0004\ntype: short\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: gone.raw\n",
    )
    .unwrap();
    assert_err_names(&nhdr, "gone.raw");

    // A detached data file is read only inside the header's folder, and only when it is a
    // regular file: a header could otherwise load /etc/shadow as voxels, or hang on a FIFO.
    let voxels = dir.join("voxels.raw");
    std::fs::write(&voxels, [0u8; 16]).unwrap();
    let outside = std::env::temp_dir().join(format!("voyage-outside-{}.raw", std::process::id()));
    std::fs::write(&outside, [0u8; 16]).unwrap();
    std::os::unix::fs::symlink(&outside, dir.join("link.raw")).unwrap();
    let fifo = dir.join("fifo.raw");
    assert!(
        std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success()
    );
    let header = |data: &str| {
        format!("NDims = 3\nDimSize = 2 2 2\nElementType = MET_SHORT\nElementDataFile = {data}\n")
    };
    for (data, why) in [
        (
            outside.to_str().unwrap(),
            "only a file in the header's folder",
        ),
        ("../voxels.raw", "only a file in the header's folder"),
        ("link.raw", "leads out of the header's folder"),
        ("fifo.raw", "not a regular file"),
    ] {
        std::fs::write(&mhd, header(data)).unwrap();
        assert_err_names(&mhd, why);
        std::fs::write(
            &nhdr,
            format!("NRRD0004\ntype: short\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: {data}\n"),
        )
        .unwrap();
        assert_err_names(&nhdr, why);
    }
    std::fs::write(&mhd, header("voxels.raw")).unwrap();
    assert!(load_any(&mhd).is_ok());
    std::fs::remove_file(&outside).unwrap();
    // Small text files (findings): a device or a FIFO never ends.
    for path in [std::path::Path::new("/dev/zero"), fifo.as_path()] {
        let err = voyage_io::read_small_text(path, 1 << 20)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("not a regular file"), "{err}");
    }

    let bad = dir.join("badtype.nrrd");
    std::fs::write(
        &bad,
        "NRRD0004\ntype: quaternion\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\n",
    )
    .unwrap();
    assert_err_names(&bad, "type: quaternion is not supported");
    let bad = dir.join("badtype.mha");
    std::fs::write(
        &bad,
        "NDims = 3\nDimSize = 2 2 2\nElementType = MET_STRING\nElementDataFile = LOCAL\n",
    )
    .unwrap();
    assert_err_names(&bad, "ElementType = MET_STRING is not supported");
    let bad = dir.join("bad-encoding.nrrd");
    std::fs::write(
        &bad,
        "NRRD0004\ntype: short\ndimension: 3\nsizes: 2 2 2\nencoding: bzip2\n\n",
    )
    .unwrap();
    assert_err_names(&bad, "encoding: bzip2 is not supported");
    assert!(matches!(
        load_any(&dir.join("absent.nii")),
        Err(voyage_core::Error::Io { .. })
    ));
}

/// Mutated and cut copies of valid files: every load returns, Ok or Err, without panic.
/// `VOYAGE_FUZZ_ROUNDS` raises the number of mutations per file (default 150).
#[test]
fn mutated_files_never_panic() {
    let rounds: usize = std::env::var("VOYAGE_FUZZ_ROUNDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(150);
    let dir = TempDir::new("mutate");
    let vol = synthetic(oblique());
    let mut small = Geometry::new([5, 4, 3], [0.8, 0.9, 1.5], [1.0, 2.0, 3.0]).unwrap();
    small.direction = TURNED_FLIPPED;
    let small = Volume::from_vec(small, (0..60).map(|v| v * 100 - 3000).collect()).unwrap();
    let mut seed = 7u64;
    let mut next = move || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 33) as usize
    };
    let savers: [(&str, Saver); 5] = [
        ("m.nii", nifti::save_i16),
        ("m.nii.gz", nifti::save_i16),
        ("m.mha", metaimage::save),
        ("m.nrrd", nrrd::save),
        ("m.mhd", metaimage::save),
    ];
    for (name, save) in savers {
        for v in [&vol, &small] {
            let p = dir.join(name);
            save(&p, v).unwrap();
            let original = std::fs::read(&p).unwrap();
            let header_len = original.len().min(400);
            for round in 0..rounds {
                let mut bytes = original.clone();
                match round % 3 {
                    0 => bytes.truncate(next() % bytes.len()),
                    1 => {
                        for _ in 0..1 + next() % 4 {
                            let at = next() % header_len;
                            bytes[at] = next() as u8;
                        }
                    }
                    _ => {
                        let at = next() % bytes.len();
                        bytes[at] ^= 1 << (next() % 8);
                    }
                }
                std::fs::write(&p, &bytes).unwrap();
                if let Ok(l) = load_any(&p) {
                    assert_eq!(l.volume.data().len(), l.volume.geometry().len());
                }
            }
        }
    }
}
