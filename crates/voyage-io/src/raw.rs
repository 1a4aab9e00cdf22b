//! What the NIfTI, MetaImage and NRRD readers and writers share: the voxel types written,
//! element types, byte order, streaming conversion to `i16` with rescale, truncation checks,
//! text header lines, direction checks.

use std::{
    io::{BufRead, BufReader, Read},
    path::Path,
};

use glam::{DMat3, DVec3};

use voyage_core::{Error, Geometry, Result, check_dims};

/// Opens a volume file for buffered reading, with its length; an empty file is an error.
pub fn open_nonempty(path: &Path) -> Result<(BufReader<std::fs::File>, u64)> {
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
    if len == 0 {
        return Err(Error::format(path, "empty file"));
    }
    Ok((BufReader::with_capacity(1 << 16, file), len))
}

/// At most 80 characters of a line, for messages.
pub fn clip(line: &str) -> String {
    line.chars().take(80).collect()
}

/// Stored element type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scalar {
    U8,
    I8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    pub fn size(self) -> usize {
        match self {
            Scalar::U8 | Scalar::I8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Endian {
    Little,
    Big,
}

/// value · slope + inter, a linear map from stored values to HU.
#[derive(Clone, Copy, Debug)]
pub struct Rescale {
    slope: f64,
    inter: f64,
}

impl Rescale {
    /// None for the identity, so that the fast integer paths are taken.
    pub fn new(slope: f64, inter: f64) -> Option<Rescale> {
        (slope.is_finite() && inter.is_finite() && slope != 0.0 && (slope, inter) != (1.0, 0.0))
            .then_some(Rescale { slope, inter })
    }
}

/// HU given to NaN voxels: air, the value of "nothing here".
pub const NAN_HU: i16 = -1024;

/// Voxels plus what happened to the values on the way.
pub struct Decoded {
    pub voxels: Vec<i16>,
    pub nan: u64,
    pub clamped: u64,
}

impl Decoded {
    /// Notes for `Meta::notes` when values were altered.
    pub fn notes(&self) -> Vec<String> {
        let mut notes = Vec::new();
        if self.nan > 0 {
            notes.push(format!("{} NaN voxels set to {NAN_HU}", self.nan));
        }
        if self.clamped > 0 {
            notes.push(format!(
                "{} voxels outside the i16 range were clamped",
                self.clamped
            ));
        }
        notes
    }
}

/// Unit columns of a direction matrix, from axis vectors that may carry a length; fails
/// when they are not perpendicular (shear) or have zero or non-finite length.
pub fn direction_from_axes(axes: [DVec3; 3]) -> Result<(DVec3, DMat3), String> {
    decompose(DMat3::from_cols(axes[0], axes[1], axes[2]))
}

/// Splits an orthogonal matrix of axis steps into spacing (column lengths) and direction
/// (unit columns).
pub fn decompose(m: DMat3) -> Result<(DVec3, DMat3), String> {
    check_orthogonal(m)?;
    let spacing = DVec3::new(m.x_axis.length(), m.y_axis.length(), m.z_axis.length());
    let dir = DMat3::from_cols(
        m.x_axis / spacing.x,
        m.y_axis / spacing.y,
        m.z_axis / spacing.z,
    );
    Ok((spacing, dir))
}

/// Cosine between two voxel axes above which the affine is taken to be sheared (≈0.06°).
const SHEAR_TOLERANCE: f64 = 1e-3;

/// Fails when two voxel axes are not perpendicular (a sheared affine has no place in a
/// spacing + rotation geometry), or when an axis has zero or non-finite length.
pub fn check_orthogonal(m: DMat3) -> Result<(), String> {
    let cols = [m.x_axis, m.y_axis, m.z_axis];
    for (a, c) in cols.iter().enumerate() {
        let len = c.length();
        if !len.is_finite() || len <= 0.0 {
            return Err(format!(
                "voxel axis {a} has length {len} (affine columns {cols:?})"
            ));
        }
    }
    for (a, b) in [(0, 1), (0, 2), (1, 2)] {
        let cos = cols[a].dot(cols[b]) / (cols[a].length() * cols[b].length());
        if cos.abs() > SHEAR_TOLERANCE {
            return Err(format!(
                "voxel axes {a} and {b} are not perpendicular (cosine {cos:.5}): sheared affines are not supported"
            ));
        }
    }
    Ok(())
}

/// At most this many bytes of text header (MetaImage, NRRD) before the data.
const MAX_HEADER: u64 = 1 << 20;
/// At most this many bytes per header line.
const MAX_LINE: u64 = 1 << 16;

/// Reads a text header line by line from a buffered stream, counting the bytes it
/// consumed (the data's offset) and refusing binary or endless headers.
pub struct HeaderLines<'a> {
    pub r: &'a mut dyn BufRead,
    pub consumed: u64,
    path: &'a Path,
}

impl<'a> HeaderLines<'a> {
    pub fn new(path: &'a Path, r: &'a mut dyn BufRead) -> Self {
        HeaderLines {
            r,
            consumed: 0,
            path,
        }
    }

    /// The next line without its line ending, or None at the end of the file.
    pub fn next_line(&mut self) -> Result<Option<String>> {
        let mut buf = Vec::new();
        let n = (&mut *self.r)
            .take(MAX_LINE)
            .read_until(b'\n', &mut buf)
            .map_err(|e| Error::io(self.path, e))?;
        if n == 0 {
            return Ok(None);
        }
        self.consumed += n as u64;
        if self.consumed > MAX_HEADER || (n as u64 == MAX_LINE && !buf.ends_with(b"\n")) {
            return Err(Error::format(
                self.path,
                "header is too long: is this really a text header?",
            ));
        }
        while buf.last().is_some_and(|&c| c == b'\n' || c == b'\r') {
            buf.pop();
        }
        String::from_utf8(buf).map(Some).map_err(|_| {
            Error::format(
                self.path,
                format!("header line ending at byte {} is not text", self.consumed),
            )
        })
    }
}

/// Parses exactly `count` whitespace-separated numbers of a header field.
pub fn numbers<T: std::str::FromStr>(
    key: &str,
    value: &str,
    count: usize,
) -> Result<Vec<T>, String> {
    let v: Vec<T> = value
        .split_whitespace()
        .map(|t| t.parse::<T>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("{key}: cannot read numbers from \"{value}\""))?;
    if v.len() != count {
        return Err(format!(
            "{key}: expected {count} numbers, found {} in \"{value}\"",
            v.len()
        ));
    }
    Ok(v)
}

/// Checks header dims and returns them with the voxel count.
pub fn dims3(path: &Path, d: &[u64]) -> Result<([usize; 3], usize)> {
    let d: [u64; 3] = d
        .try_into()
        .map_err(|_| Error::format(path, format!("expected 3 dimensions, found {}", d.len())))?;
    check_dims(d).map_err(super::at(path))?;
    let dims = d.map(|v| v as usize);
    Ok((dims, dims[0] * dims[1] * dims[2]))
}

/// Builds and validates the geometry from LPS origin, spacing and unit direction.
pub fn geometry(
    path: &Path,
    dims: [usize; 3],
    spacing: DVec3,
    origin: DVec3,
    dir: DMat3,
) -> Result<Geometry> {
    let mut g = Geometry {
        dims,
        spacing: spacing.to_array(),
        origin: origin.to_array(),
        direction: [[0.0; 3]; 3],
    };
    g.set_direction_mat(dir);
    g.validate().map_err(super::at(path))?;
    Ok(g)
}

/// Re-labels an error about a separate data file so that the one-line message names
/// the header the user opened as well as the data file.
pub fn in_data_file<'a>(header: &'a Path, data: &'a Path) -> impl Fn(Error) -> Error + 'a {
    move |e| {
        let msg = match e {
            Error::Format { msg, .. } | Error::Invalid(msg) => msg,
            Error::Io { err, .. } => err.to_string(),
        };
        Error::format(header, format!("data file {}: {msg}", data.display()))
    }
}

pub fn is_gzip(bytes: &[u8]) -> bool {
    bytes.starts_with(&[0x1f, 0x8b])
}

/// The most bytes `compressed` bytes of deflate data can expand to (deflate's ratio
/// is at most 1032:1): a header promising more is truncated, whatever the stream holds.
pub fn max_inflated_len(compressed: u64) -> u64 {
    compressed.saturating_mul(1032).saturating_add(1024)
}

/// How long the (decoded) stream holding the voxels can be, known before reading it.
#[derive(Clone, Copy, Debug)]
pub enum Avail {
    /// An uncompressed file of this many bytes.
    Exact(u64),
    /// A compressed stream that cannot expand beyond this many bytes.
    AtMost(u64),
}

impl Avail {
    /// Refuses, before anything is allocated, a header whose `expected` voxel bytes
    /// starting at `offset` cannot fit in the stream.
    pub fn check(self, path: &Path, offset: u64, expected: u64) -> Result<()> {
        match self {
            Avail::Exact(len) if len.saturating_sub(offset) < expected => Err(Error::format(
                path,
                truncated_msg(expected, len.saturating_sub(offset)),
            )),
            Avail::AtMost(max) if max.saturating_sub(offset) < expected => Err(Error::format(
                path,
                format!(
                    "truncated: expected {expected} bytes of voxel data, but the compressed file can hold at most {}",
                    max.saturating_sub(offset)
                ),
            )),
            _ => Ok(()),
        }
    }
}

pub fn truncated_msg(expected: u64, found: u64) -> String {
    format!("truncated: expected {expected} bytes of voxel data, found {found}")
}

/// Reads until `buf` is full or the stream ends; returns the count. A decoder's
/// "unexpected end of file" counts as the end, so truncation is reported by length.
pub fn fill(r: &mut dyn Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match r.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => break,
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

/// A read error inside a file: corrupt compressed data is a format problem.
pub fn read_error(path: &Path, e: std::io::Error) -> Error {
    match e.kind() {
        std::io::ErrorKind::InvalidData | std::io::ErrorKind::InvalidInput => {
            Error::format(path, format!("corrupt compressed data: {e}"))
        }
        _ => Error::io(path, e),
    }
}

/// How many bytes a [`skip`] passed over.
pub struct Skipped {
    wanted: u64,
    got: u64,
}

impl Skipped {
    /// Fails when the stream ended before the data's start (`data_start` is for the message).
    pub fn check(&self, path: &Path, data_start: u64) -> Result<()> {
        if self.got < self.wanted {
            return Err(Error::format(
                path,
                format!(
                    "truncated: voxel data should start at byte {data_start}, but the file ends before"
                ),
            ));
        }
        Ok(())
    }
}

/// Reads and discards `n` bytes (works on decompressing streams, which cannot seek).
pub fn skip(r: &mut dyn Read, n: u64) -> std::io::Result<Skipped> {
    let mut buf = [0u8; 8192];
    let mut left = n;
    while left > 0 {
        let want = left.min(buf.len() as u64) as usize;
        let got = fill(r, &mut buf[..want])?;
        left -= got as u64;
        if got < want {
            break;
        }
    }
    Ok(Skipped {
        wanted: n,
        got: n - left,
    })
}

/// Reads a compressed stream to its end after the voxels, so that the decoder checks
/// the trailer's CRC-32 (gzip) or Adler-32 (zlib): without this, damaged data that still
/// inflates would load silently. A stream cut inside its trailer is refused; trailing
/// bytes after the stream are ignored, up to a bound.
pub fn finish_compressed(path: &Path, r: &mut dyn Read) -> Result<()> {
    const MAX_TRAILING: u64 = 1 << 26;
    let drained = std::io::copy(&mut r.take(MAX_TRAILING), &mut std::io::sink());
    match drained {
        Ok(_) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => Err(Error::format(
            path,
            "truncated: the compressed data ends before its checksum (the voxels cannot be verified)",
        )),
        Err(e) => Err(read_error(path, e)),
    }
}

/// Bytes decoded per step: a multiple of every element size, small enough for cache.
const CHUNK: usize = 1 << 20;

/// Streams exactly `n` elements of type `ty` from `r` into a new `i16` vector, applying
/// the rescale. The caller has validated `n`; the output is allocated once, exactly.
pub fn read_voxels(
    path: &Path,
    r: &mut dyn Read,
    n: usize,
    ty: Scalar,
    endian: Endian,
    rescale: Option<Rescale>,
) -> Result<Decoded> {
    let expected = n.checked_mul(ty.size()).ok_or_else(|| {
        Error::format(path, format!("{n} voxels of {} bytes overflow", ty.size()))
    })?;
    let mut voxels = Vec::new();
    voxels
        .try_reserve_exact(n)
        .map_err(|_| Error::format(path, format!("cannot allocate {n} voxels")))?;
    let mut out = Decoded {
        voxels,
        nan: 0,
        clamped: 0,
    };
    let mut buf = vec![0u8; CHUNK.min(expected)];
    let mut done = 0usize;
    while done < expected {
        let want = (expected - done).min(CHUNK);
        let got = fill(r, &mut buf[..want]).map_err(|e| read_error(path, e))?;
        done += got;
        if got < want {
            return Err(Error::format(
                path,
                truncated_msg(expected as u64, done as u64),
            ));
        }
        convert(&buf[..want], ty, endian == Endian::Big, rescale, &mut out);
    }
    Ok(out)
}

/// Elements of `N` bytes, decoded in the file's byte order.
fn samples<const N: usize, T>(
    bytes: &[u8],
    big: bool,
    from_le: impl Fn([u8; N]) -> T,
) -> impl Iterator<Item = T> {
    bytes.as_chunks::<N>().0.iter().map(move |c| {
        let mut c = *c;
        if big {
            c.reverse();
        }
        from_le(c)
    })
}

/// Appends the `i16` value of every element of `bytes` (a whole number of elements).
fn convert(bytes: &[u8], ty: Scalar, big: bool, rescale: Option<Rescale>, out: &mut Decoded) {
    macro_rules! go {
        ($t:ty, $n:literal) => {{
            let it = samples::<$n, $t>(bytes, big, <$t>::from_le_bytes);
            match rescale {
                None => extend_direct(it, out),
                Some(r) => extend_scaled(it.map(|v| v as f64), r, out),
            }
        }};
    }
    match ty {
        Scalar::U8 => go!(u8, 1),
        Scalar::I8 => go!(i8, 1),
        Scalar::I16 => go!(i16, 2),
        Scalar::U16 => go!(u16, 2),
        Scalar::I32 => go!(i32, 4),
        Scalar::U32 => go!(u32, 4),
        Scalar::F32 => go!(f32, 4),
        Scalar::F64 => go!(f64, 8),
    }
}

/// Stored values that become `i16` without a rescale.
trait ToI16: Copy {
    /// The value rounded and saturated, and whether it had to be clamped (NaN aside).
    fn to_i16(self) -> (i16, bool);
    fn is_nan(self) -> bool {
        false
    }
}

macro_rules! int_to_i16 {
    ($($t:ty),*) => {$(
        impl ToI16 for $t {
            #[inline]
            fn to_i16(self) -> (i16, bool) {
                let v = i64::from(self);
                let c = v.clamp(i16::MIN.into(), i16::MAX.into());
                (c as i16, c != v)
            }
        }
    )*};
}
int_to_i16!(u8, i8, i16, u16, i32, u32);

impl ToI16 for f32 {
    fn to_i16(self) -> (i16, bool) {
        f64::from(self).to_i16()
    }
    fn is_nan(self) -> bool {
        f32::is_nan(self)
    }
}

impl ToI16 for f64 {
    #[inline]
    fn to_i16(self) -> (i16, bool) {
        let r = self.round();
        (r as i16, !(-32768.0..=32767.0).contains(&r))
    }
    fn is_nan(self) -> bool {
        f64::is_nan(self)
    }
}

fn extend_direct<T: ToI16>(it: impl Iterator<Item = T>, out: &mut Decoded) {
    let mut clamped = 0u64;
    let mut nan = 0u64;
    out.voxels.extend(it.map(|v| {
        if v.is_nan() {
            nan += 1;
            return NAN_HU;
        }
        let (x, c) = v.to_i16();
        clamped += u64::from(c);
        x
    }));
    out.clamped += clamped;
    out.nan += nan;
}

fn extend_scaled(it: impl Iterator<Item = f64>, r: Rescale, out: &mut Decoded) {
    extend_direct(it.map(|v| v * r.slope + r.inter), out);
}

/// Voxel types voyage writes (NIfTI, MetaImage, NRRD), with their NIfTI datatype code.
pub trait Voxel: Copy {
    const DATATYPE: i16;
    const BITPIX: i16;
    /// Appends the little-endian bytes of `values` to `out`.
    fn extend_le(values: &[Self], out: &mut Vec<u8>);
}

macro_rules! voxel {
    ($t:ty, $code:expr, $n:literal) => {
        impl Voxel for $t {
            const DATATYPE: i16 = $code;
            const BITPIX: i16 = 8 * $n;
            fn extend_le(values: &[Self], out: &mut Vec<u8>) {
                let start = out.len();
                out.resize(start + values.len() * $n, 0);
                let (dst, _) = out[start..].as_chunks_mut::<$n>();
                for (d, v) in dst.iter_mut().zip(values) {
                    *d = v.to_le_bytes();
                }
            }
        }
    };
}
voxel!(u8, 2, 1);
voxel!(i16, 4, 2);
voxel!(i32, 8, 4);
voxel!(f32, 16, 4);
voxel!(u16, 512, 2);
