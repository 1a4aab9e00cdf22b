//! Lenient opening: the file meta group parsed here and rewritten for dicom-rs (real files
//! break its rules), deflated data sets inflated within bounds, and every element length
//! walked and checked against the file before dicom-rs allocates for it.

use std::path::Path;

use dicom_core::Tag;
use dicom_encoding::transfer_syntax::{Endianness, TransferSyntaxIndex};
use dicom_object::{DefaultDicomObject, OpenFileOptions};
use dicom_transfer_syntax_registry::TransferSyntaxRegistry;

use crate::alloc_guard::capped;
use voyage_core::{Error, Result};
// ---------------------------------------------------------------------------------------------
// Lenient opening
// ---------------------------------------------------------------------------------------------

/// A library error with its causes, on one line.
pub(super) fn error_chain(e: &dyn std::error::Error) -> String {
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

/// Why [`open_dicom`] failed.
pub(super) enum OpenError {
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
    pub(super) fn into_error(self, path: &Path, what: &str) -> Error {
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
pub(super) fn ends_early(e: &(dyn std::error::Error + 'static)) -> bool {
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
pub(super) const MAX_META_BYTES: usize = 1 << 20;

/// Opens a DICOM Part 10 file, reading up to (not including) `until` when given.
///
/// The file meta group is parsed here and handed to dicom-rs rewritten, because real files
/// often break rules that dicom-rs enforces there: a missing group length, an application
/// entity title longer than 16 characters (the transfer-syntax test files have one), padding
/// in the wrong place. Only the elements needed to read the data set are kept.
pub(super) fn open_dicom(
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
    let size = file.metadata().map_err(OpenError::Io)?.len();
    if let Some(layout) = Layout::of(&meta.ts_uid) {
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
    capped(parse_bound(size), || options.from_reader(source)).map_err(OpenError::Parse)
}

/// The largest single allocation dicom-rs may make while it parses `bytes` of data set: the
/// largest value is at most the file, and its element records take a few times the bytes
/// they come from; and 2 GiB more, because where dicom-rs allocates without `try_reserve` a
/// refusal aborts the process (a corrupt 1 kB file made it allocate 766 MB and then fail
/// cleanly: that must stay an error). What is refused is what no machine should be asked for.
fn parse_bound(bytes: u64) -> usize {
    usize::try_from(bytes)
        .unwrap_or(usize::MAX)
        .saturating_mul(16)
        .saturating_add(2 << 30)
}

/// The file meta group as found, and rewritten.
pub(super) struct MetaGroup {
    /// "DICM" followed by a clean, explicit VR little endian meta group.
    pub(super) clean: Vec<u8>,
    /// Offset in the file where the data set starts.
    pub(super) end: usize,
    pub(super) ts_uid: String,
}

pub(super) const DEFLATED_EXPLICIT_LE: &str = "1.2.840.10008.1.2.1.99";
pub(super) const EXPLICIT_LE: &str = "1.2.840.10008.1.2.1";

/// A deflated data set holds at most this many times its compressed size (real ones: 2–10×);
/// more is a corrupt or hostile stream, refused before it fills the memory.
pub(super) const MAX_INFLATE_RATIO: u64 = 256;

/// Deflated explicit VR little endian: inflated here (bounded), its lengths checked like any
/// other data set's, and handed to dicom-rs as plain explicit VR little endian. dicom-rs would
/// otherwise inflate as it parses and allocate whatever a corrupt length inside announces.
pub(super) fn open_deflated(
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
    let inflated_len = inflated.len();
    let source = Cursor::new(clean).chain(Cursor::new(inflated));
    let mut options = OpenFileOptions::new().read_preamble(dicom_object::file::ReadPreamble::Never);
    if let Some(tag) = until {
        options = options.read_until(tag);
    }
    let bound = parse_bound(inflated_len as u64);
    let mut obj = capped(bound, || options.from_reader(source)).map_err(OpenError::Parse)?;
    // Report the file as it is: deflated.
    obj.meta_mut().transfer_syntax = DEFLATED_EXPLICIT_LE.to_string();
    Ok(obj)
}

/// The rewritten meta group ("DICM" + group length + elements, as `parse_meta` makes it)
/// with another transfer syntax.
pub(super) fn with_transfer_syntax(clean: &[u8], ts: &str) -> Vec<u8> {
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
pub(super) fn describe_unknown_ts(uid: &str) -> String {
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
pub(super) fn parse_meta(buf: &[u8], eof: bool) -> std::result::Result<Option<MetaGroup>, String> {
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

pub(super) fn put_meta_element(out: &mut Vec<u8>, element: u16, vr: &[u8; 2], value: &[u8]) {
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
pub(super) struct Layout {
    pub(super) explicit: bool,
    pub(super) big_endian: bool,
}

impl Layout {
    /// `None` for deflated data sets, which cannot be scanned before inflating.
    pub(super) fn of(ts_uid: &str) -> Option<Layout> {
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

    pub(super) fn u16(&self, b: &[u8]) -> u16 {
        if self.big_endian {
            u16::from_be_bytes([b[0], b[1]])
        } else {
            u16::from_le_bytes([b[0], b[1]])
        }
    }

    pub(super) fn u32(&self, b: &[u8]) -> u32 {
        if self.big_endian {
            u32::from_be_bytes([b[0], b[1], b[2], b[3]])
        } else {
            u32::from_le_bytes([b[0], b[1], b[2], b[3]])
        }
    }
}

pub(super) enum Scan {
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

pub(super) const UNDEFINED: u32 = 0xFFFF_FFFF;
pub(super) const MAX_NESTING: usize = 64;

/// Walks the element headers of a data set (descending into sequences and items) and checks
/// that every announced length fits in what is left of the file. dicom-rs allocates and zeroes
/// a buffer of the announced length before reading a value, so a corrupt length would
/// otherwise cost gigabytes of memory before the read fails. With `whole`, the walk goes on
/// through the pixel data (each fragment of encapsulated data too) to the end of the file, as
/// the full read will; without, it stops at the pixel data, where the header read stops.
pub(super) fn scan_lengths(
    buf: &[u8],
    start: usize,
    file_size: u64,
    layout: Layout,
    whole: bool,
) -> Scan {
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
pub(super) fn scan_fragments(
    buf: &[u8],
    start: usize,
    file_size: u64,
    layout: Layout,
) -> Result<usize, Scan> {
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
pub(super) fn element_header(buf: &[u8], pos: usize, layout: Layout) -> Option<(usize, u32, bool)> {
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

pub(super) fn check_len(
    group: u16,
    element: u16,
    len: u32,
    value: usize,
    file_size: u64,
) -> Option<Scan> {
    let left = file_size.saturating_sub(value as u64);
    (len != UNDEFINED && u64::from(len) > left).then(|| {
        Scan::Bad(format!(
            "the file is cut short or corrupt: element ({group:04X},{element:04X}) announces {len} bytes, but only {left} remain"
        ))
    })
}
