//! Writing a volume as a DICOM CT series: one CT Image Storage file per k-slice, explicit VR
//! little endian, 16-bit signed HU with RescaleSlope 1 and RescaleIntercept 0 (so the values
//! round-trip exactly).
//!
//! The files are encoded by hand rather than through an in-memory DICOM object: the layout is
//! fixed and small, and this keeps a 400-slice series down to the cost of writing its bytes.
//! UIDs are deterministic (`2.25.<128-bit hash>` of the geometry, the voxels and the options),
//! so writing the same volume twice gives identical files. The patient is always the phantom
//! ("Phantom^Voyage", "PHANTOM"): these are test and export series, never real patient data.

use std::path::Path;

use rayon::prelude::*;

use super::atomic::write_atomic;
use voyage_core::{Error, Result, Volume};

/// CT Image Storage.
pub const CT_IMAGE_STORAGE: &str = "1.2.840.10008.5.1.4.1.1.2";
/// Explicit VR Little Endian.
pub const EXPLICIT_VR_LE: &str = "1.2.840.10008.1.2.1";
/// voyage's implementation class UID (a fixed 2.25 UID).
const IMPLEMENTATION_CLASS_UID: &str = "2.25.205113376516394311128432474713652180993";
const IMPLEMENTATION_VERSION: &str = "VOYAGE_0_1";

/// Choices for [`write_series_with`].
#[derive(Clone, Debug)]
pub struct SeriesWriteOptions {
    pub series_description: String,
    pub series_number: u32,
    /// Mixed into every UID: two series written from the same volume with different seeds get
    /// different UIDs; the same seed gives the same UIDs.
    pub uid_seed: u64,
    /// PatientPosition (0018,5100), e.g. "HFS" (head first, supine) or "HFP" (prone), which
    /// tells a reader which way gravity pointed; `None` leaves the element out.
    pub patient_position: Option<String>,
    /// StudyDate (0008,0020), DICOM DA "YYYYMMDD"; `None` leaves it empty.
    pub study_date: Option<String>,
    /// The files are named PREFIX0000.dcm, PREFIX0001.dcm ...: two series of one exam can
    /// share a folder.
    pub file_prefix: String,
}

impl Default for SeriesWriteOptions {
    fn default() -> Self {
        SeriesWriteOptions {
            series_description: "voyage volume".into(),
            series_number: 1,
            uid_seed: 0,
            patient_position: None,
            study_date: None,
            file_prefix: "slice".into(),
        }
    }
}

/// Writes `vol` as a CT series into `dir` (created if missing) with default options.
pub fn write_series(dir: &Path, vol: &Volume<i16>) -> Result<()> {
    write_series_with(dir, vol, &SeriesWriteOptions::default())
}

/// Writes `vol` as a CT series into `dir`: files `slice0000.dcm`, `slice0001.dcm`, ... (the
/// prefix as `opts` says) one per
/// k-slice, each written atomically.
pub fn write_series_with(dir: &Path, vol: &Volume<i16>, opts: &SeriesWriteOptions) -> Result<()> {
    let g = vol.geometry();
    g.validate()?;
    let [nx, ny, nz] = g.dims;
    if nx > u16::MAX as usize || ny > u16::MAX as usize {
        return Err(Error::invalid(format!(
            "slices of {nx}×{ny} are too large for DICOM (at most 65535 per side)"
        )));
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let uids = SeriesUids::new(vol, opts);
    let digits = nz.saturating_sub(1).to_string().len().max(4);
    (0..nz).into_par_iter().try_for_each(|k| {
        let bytes = encode_slice(vol, k, &uids, opts);
        let path = dir.join(format!("{}{k:0digits$}.dcm", opts.file_prefix));
        write_atomic(&path, |w| w.write_all(&bytes))
    })
}

/// The UIDs shared by the series' files.
struct SeriesUids {
    study: String,
    series: String,
    frame_of_reference: String,
}

impl SeriesUids {
    fn new(vol: &Volume<i16>, opts: &SeriesWriteOptions) -> Self {
        let g = vol.geometry();
        let mut h = Hash128::new(opts.uid_seed);
        for d in g.dims {
            h.word(d as u64);
        }
        for v in g
            .spacing
            .iter()
            .chain(&g.origin)
            .chain(g.direction.iter().flatten())
        {
            h.word(v.to_bits());
        }
        let frame = h.clone();
        h.bytes(opts.series_description.as_bytes());
        h.word(u64::from(opts.series_number));
        for chunk in vol.data().chunks(4) {
            let mut w = 0u64;
            for (i, &v) in chunk.iter().enumerate() {
                w |= u64::from(v as u16) << (16 * i);
            }
            h.word(w);
        }
        let mut study = Hash128::new(opts.uid_seed);
        study.bytes(b"study");
        SeriesUids {
            study: study.uid(),
            series: h.uid(),
            frame_of_reference: frame.uid(),
        }
    }

    /// SOPInstanceUID of slice k: the series UID with the instance number appended.
    fn instance(&self, k: usize) -> String {
        format!("{}.{}", self.series, k + 1)
    }
}

/// A small 128-bit hash (two multiply-xorshift lanes): deterministic across platforms and Rust
/// versions, unlike `std`'s `DefaultHasher`. Not cryptographic, which UIDs do not need.
#[derive(Clone)]
struct Hash128 {
    a: u64,
    b: u64,
}

impl Hash128 {
    fn new(seed: u64) -> Self {
        Hash128 {
            a: 0x9E37_79B9_7F4A_7C15 ^ seed,
            b: 0xC2B2_AE3D_27D4_EB4F ^ seed.rotate_left(32),
        }
    }

    #[inline]
    fn word(&mut self, w: u64) {
        self.a = (self.a ^ w)
            .wrapping_mul(0xFF51_AFD7_ED55_8CCD)
            .rotate_left(29);
        self.b = (self.b ^ w.rotate_left(17))
            .wrapping_mul(0xC4CE_B9FE_1A85_EC53)
            .rotate_left(31)
            ^ self.a;
    }

    fn bytes(&mut self, s: &[u8]) {
        for chunk in s.chunks(8) {
            let mut buf = [0u8; 8];
            buf[..chunk.len()].copy_from_slice(chunk);
            self.word(u64::from_le_bytes(buf));
        }
        self.word(s.len() as u64);
    }

    fn finish(&self) -> u128 {
        let mix = |mut x: u64| {
            x ^= x >> 33;
            x = x.wrapping_mul(0xFF51_AFD7_ED55_8CCD);
            x ^= x >> 33;
            x = x.wrapping_mul(0xC4CE_B9FE_1A85_EC53);
            x ^ (x >> 33)
        };
        (u128::from(mix(self.a ^ self.b.rotate_left(7))) << 64)
            | u128::from(mix(self.b ^ self.a.rotate_left(13)))
    }

    /// A UID under the 2.25 root (a 128-bit number, never 0 so it has no leading zero).
    fn uid(&self) -> String {
        format!("2.25.{}", self.finish().max(1))
    }
}

/// Encodes slice k as a complete DICOM Part 10 file.
fn encode_slice(
    vol: &Volume<i16>,
    k: usize,
    uids: &SeriesUids,
    opts: &SeriesWriteOptions,
) -> Vec<u8> {
    let g = vol.geometry();
    let [nx, ny, _] = g.dims;
    let m = g.direction_mat();
    let position = g.index_to_patient(glam::DVec3::new(0.0, 0.0, k as f64));
    let (row, col) = (m.col(0), m.col(1));
    let sop_instance = uids.instance(k);

    let mut e = Encoder {
        buf: Vec::with_capacity(nx * ny * 2 + 2048),
    };
    e.buf.extend_from_slice(&[0u8; 128]);
    e.buf.extend_from_slice(b"DICM");
    e.meta_group(&sop_instance);

    e.text(0x0008, 0x0008, b"CS", "DERIVED\\SECONDARY\\AXIAL");
    e.uid(0x0008, 0x0016, CT_IMAGE_STORAGE);
    e.uid(0x0008, 0x0018, &sop_instance);
    e.text(
        0x0008,
        0x0020,
        b"DA",
        opts.study_date.as_deref().unwrap_or(""),
    );
    e.text(0x0008, 0x0030, b"TM", "");
    e.text(0x0008, 0x0050, b"SH", "");
    e.text(0x0008, 0x0060, b"CS", "CT");
    e.text(0x0008, 0x0070, b"LO", "voyage");
    e.text(0x0008, 0x0090, b"PN", "");
    e.text(0x0008, 0x103E, b"LO", &opts.series_description);
    e.text(0x0010, 0x0010, b"PN", "Phantom^Voyage");
    e.text(0x0010, 0x0020, b"LO", "PHANTOM");
    e.text(0x0010, 0x0030, b"DA", "");
    e.text(0x0010, 0x0040, b"CS", "");
    e.text(0x0018, 0x0050, b"DS", &ds(g.spacing[2]));
    e.text(0x0018, 0x0060, b"DS", "");
    e.text(0x0018, 0x0088, b"DS", &ds(g.spacing[2]));
    if let Some(position) = &opts.patient_position {
        e.text(0x0018, 0x5100, b"CS", position);
    }
    e.uid(0x0020, 0x000D, &uids.study);
    e.uid(0x0020, 0x000E, &uids.series);
    e.text(0x0020, 0x0010, b"SH", "");
    e.text(0x0020, 0x0011, b"IS", &opts.series_number.to_string());
    e.text(0x0020, 0x0013, b"IS", &(k + 1).to_string());
    e.text(0x0020, 0x0020, b"CS", "");
    e.text(0x0020, 0x0032, b"DS", &ds_list(&position.to_array()));
    e.text(
        0x0020,
        0x0037,
        b"DS",
        &ds_list(&[row.x, row.y, row.z, col.x, col.y, col.z]),
    );
    e.uid(0x0020, 0x0052, &uids.frame_of_reference);
    e.text(0x0020, 0x1040, b"LO", "");
    e.us(0x0028, 0x0002, 1);
    e.text(0x0028, 0x0004, b"CS", "MONOCHROME2");
    e.us(0x0028, 0x0010, ny as u16);
    e.us(0x0028, 0x0011, nx as u16);
    // PixelSpacing: between rows (along j) first, then between columns (along i).
    e.text(
        0x0028,
        0x0030,
        b"DS",
        &ds_list(&[g.spacing[1], g.spacing[0]]),
    );
    e.us(0x0028, 0x0100, 16);
    e.us(0x0028, 0x0101, 16);
    e.us(0x0028, 0x0102, 15);
    e.us(0x0028, 0x0103, 1);
    e.text(0x0028, 0x1052, b"DS", "0");
    e.text(0x0028, 0x1053, b"DS", "1");
    e.text(0x0028, 0x1054, b"LO", "HU");
    e.pixel_data(vol.slice_k(k));
    e.buf
}

/// Explicit VR little endian element writer.
struct Encoder {
    buf: Vec<u8>,
}

impl Encoder {
    fn header(&mut self, group: u16, element: u16, vr: &[u8; 2], len: usize) {
        self.buf.extend_from_slice(&group.to_le_bytes());
        self.buf.extend_from_slice(&element.to_le_bytes());
        self.buf.extend_from_slice(vr);
        if matches!(vr, b"OB" | b"OW" | b"SQ" | b"UN" | b"UT" | b"UC" | b"UR") {
            self.buf.extend_from_slice(&[0, 0]);
            self.buf.extend_from_slice(&(len as u32).to_le_bytes());
        } else {
            self.buf.extend_from_slice(&(len as u16).to_le_bytes());
        }
    }

    /// A text value, padded with a space to even length.
    fn text(&mut self, group: u16, element: u16, vr: &[u8; 2], value: &str) {
        self.padded(group, element, vr, value.as_bytes(), b' ');
    }

    /// A UID, padded with NUL to even length.
    fn uid(&mut self, group: u16, element: u16, value: &str) {
        self.padded(group, element, b"UI", value.as_bytes(), 0);
    }

    fn padded(&mut self, group: u16, element: u16, vr: &[u8; 2], value: &[u8], pad: u8) {
        let len = value.len() + value.len() % 2;
        self.header(group, element, vr, len);
        self.buf.extend_from_slice(value);
        if value.len() % 2 == 1 {
            self.buf.push(pad);
        }
    }

    fn us(&mut self, group: u16, element: u16, value: u16) {
        self.header(group, element, b"US", 2);
        self.buf.extend_from_slice(&value.to_le_bytes());
    }

    fn pixel_data(&mut self, values: &[i16]) {
        self.header(0x7FE0, 0x0010, b"OW", values.len() * 2);
        self.buf.reserve(values.len() * 2);
        for v in values {
            self.buf.extend_from_slice(&v.to_le_bytes());
        }
    }

    /// The file meta information group (always explicit VR little endian), with its length.
    fn meta_group(&mut self, sop_instance: &str) {
        let mut meta = Encoder {
            buf: Vec::with_capacity(256),
        };
        meta.header(0x0002, 0x0001, b"OB", 2);
        meta.buf.extend_from_slice(&[0, 1]);
        meta.uid(0x0002, 0x0002, CT_IMAGE_STORAGE);
        meta.uid(0x0002, 0x0003, sop_instance);
        meta.uid(0x0002, 0x0010, EXPLICIT_VR_LE);
        meta.uid(0x0002, 0x0012, IMPLEMENTATION_CLASS_UID);
        meta.text(0x0002, 0x0013, b"SH", IMPLEMENTATION_VERSION);
        self.header(0x0002, 0x0000, b"UL", 4);
        self.buf
            .extend_from_slice(&(meta.buf.len() as u32).to_le_bytes());
        self.buf.extend_from_slice(&meta.buf);
    }
}

/// A decimal string of at most 16 characters (the DS limit) as close to `v` as that allows.
fn ds(v: f64) -> String {
    let v = if v == 0.0 { 0.0 } else { v }; // no "-0"
    for decimals in (0..=15).rev() {
        let s = format!("{v:.decimals$}");
        let s = if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        };
        let s = if s == "-0" { "0".to_string() } else { s };
        if s.len() <= 16 {
            return s;
        }
    }
    format!("{v:.3e}")
}

fn ds_list(values: &[f64]) -> String {
    values.iter().map(|&v| ds(v)).collect::<Vec<_>>().join("\\")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimal_strings_fit_and_are_close() {
        for v in [
            0.0,
            -0.0,
            1.0,
            -161.399994,
            std::f64::consts::FRAC_1_SQRT_2,
            -0.123_456_789_012_345_68,
            1e-12,
            123456.789012345,
            -1.0e-7,
        ] {
            let s = ds(v);
            assert!(s.len() <= 16, "{s}");
            let back: f64 = s.parse().unwrap();
            assert!((back - v).abs() < 1e-9 * v.abs().max(1.0), "{v} → {s}");
        }
        assert_eq!(ds(2.5), "2.5");
        assert_eq!(ds(-0.0), "0");
    }

    #[test]
    fn uids_are_deterministic_and_valid() {
        let mut h = Hash128::new(7);
        h.bytes(b"abc");
        let uid = h.uid();
        assert!(uid.starts_with("2.25.") && uid.len() <= 64);
        assert!(!uid[5..].starts_with('0'));
        let mut h2 = Hash128::new(7);
        h2.bytes(b"abc");
        assert_eq!(uid, h2.uid());
        let mut h3 = Hash128::new(8);
        h3.bytes(b"abc");
        assert_ne!(uid, h3.uid());
    }
}
