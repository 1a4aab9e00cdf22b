//! The pixel pass: each slice's pixel data (native bytes straight from the file, the rest
//! through dicom-rs and its codecs, RLE by hand), converted to HU with the slice's own rescale.

use std::path::Path;

use dicom_core::{
    Tag,
    value::{PrimitiveValue, Value},
};
use dicom_dictionary_std::tags;
use dicom_encoding::transfer_syntax::{Endianness, TransferSyntaxIndex};
use dicom_object::DefaultDicomObject;
use dicom_transfer_syntax_registry::TransferSyntaxRegistry;
use rayon::prelude::*;

use super::header::{Header, PixelFormat, Rescale, file_name, guarded, uint};
use super::lenient::{OpenError, error_chain, open_dicom};
use super::stack::{SliceRef, build_stack, correct_tilt};
use crate::{Format, Loaded, Meta};
use voyage_core::{Error, Result, Volume};
// ---------------------------------------------------------------------------------------------
// Pixel pass
// ---------------------------------------------------------------------------------------------

/// Loads the chosen files as one volume.
pub(super) fn load_series(headers: Vec<Header>) -> Result<Loaded> {
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
        let (g, d, note) = correct_tilt(&geometry, &data, shear).map_err(crate::at(&first.path))?;
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
    let volume = Volume::from_vec(geometry, data).map_err(crate::at(&first.path))?;
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

pub(super) fn transfer_syntax_names(headers: &[Header]) -> Vec<String> {
    let mut names: Vec<String> = Vec::new();
    for h in headers {
        let name = ts_name(&h.ts_uid);
        if !names.contains(&name) {
            names.push(name);
        }
    }
    names
}

pub(super) fn ts_name(uid: &str) -> String {
    TransferSyntaxRegistry
        .get(uid)
        .map(|ts| ts.name().to_string())
        .unwrap_or_else(|| uid.to_string())
}

/// Transfer syntaxes that are, or may be, lossy: JPEG baseline/extended/progressive, JPEG-LS
/// near-lossless, JPEG 2000 and HTJ2K (lossy allowed), JPEG XL.
pub(super) fn is_lossy(uid: &str) -> bool {
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
pub(super) fn read_slices(
    headers: &[Header],
    slices: &[SliceRef],
    dims: [usize; 3],
) -> Result<Vec<i16>> {
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
pub(super) enum Raw {
    /// 16-bit words in host order (native OW data, already byte-swapped for big endian).
    Words(Vec<u16>),
    /// Bytes from `start` on: 8-bit samples, or 16-bit samples little endian (codec output,
    /// OB data, or a whole file read by the fast path).
    Bytes(Vec<u8>, usize),
}

impl Raw {
    pub(super) fn byte_len(&self) -> usize {
        match self {
            Raw::Words(w) => w.len() * 2,
            Raw::Bytes(b, start) => b.len() - start,
        }
    }
}

/// Reads a whole file and returns its pixel data, decoded if encapsulated.
pub(super) fn read_pixel_data(h: &Header) -> Result<Raw> {
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
pub(super) fn native_fast_path(h: &Header, expected: usize) -> Result<Option<Raw>> {
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

pub(super) fn extract_pixels(
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

pub(super) const RLE_LOSSLESS: &str = "1.2.840.10008.1.2.5";

/// What an RLE frame decodes to.
#[derive(Clone, Copy)]
pub(super) struct RleShape {
    pub(super) pixels: usize,
    pub(super) bytes_per_sample: usize,
    pub(super) frames: usize,
}

impl RleShape {
    pub(super) fn of(obj: &DefaultDicomObject) -> std::result::Result<RleShape, String> {
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
pub(super) fn decode_rle(
    fragments: &[Vec<u8>],
    shape: RleShape,
) -> std::result::Result<Vec<u8>, String> {
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
pub(super) fn unpack_bits(
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
pub(super) fn convert_frame(
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
pub(super) struct Unpack {
    pub(super) shift: u32,
    pub(super) mask: u32,
    /// 32 − BitsStored: shifting left then arithmetic-right by this extends the sign.
    pub(super) sign_shift: u32,
    pub(super) signed: bool,
}

impl Unpack {
    pub(super) fn new(f: PixelFormat) -> Self {
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
pub(super) struct Hu {
    pub(super) slope: f64,
    pub(super) intercept: f64,
    pub(super) integer_intercept: Option<i32>,
}

impl Hu {
    pub(super) fn new(r: Rescale) -> Self {
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
pub(super) fn convert(src: impl Iterator<Item = u32>, u: Unpack, hu: Hu, out: &mut [i16]) {
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
pub(super) fn rescale_all(src: impl Iterator<Item = i32>, hu: Hu, out: &mut [i16]) {
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
