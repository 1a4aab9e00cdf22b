//! MetaImage (ITK): .mha with the voxels after the header (`ElementDataFile = LOCAL`), or
//! a .mhd header naming a separate data file, relative to the header's folder.
//!
//! Conventions (as ITK's MetaImageIO reads them):
//! - World coordinates are LPS already: `Offset` (or `Origin`, `Position`) is the LPS
//!   position of voxel (0,0,0)'s centre, and needs no conversion.
//! - `TransformMatrix` (or `Rotation`, `Orientation`) lists nine numbers in which each
//!   consecutive triple is the direction of one voxel axis: numbers 0–2 are the i axis,
//!   3–5 the j axis, 6–8 the k axis. ITK calls `SetDirection(i, triple i)`, so the triples
//!   are the *columns* of voyage's `direction`. `AnatomicalOrientation` is informational
//!   and ignored (ITK ignores it too).
//! - `ElementSpacing` gives the spacing; `ElementSize` is used only when it is absent.
//! - `CompressedData = True` data is zlib (or gzip, which MetaIO also accepts), read up to
//!   `CompressedDataSize` bytes when given. `HeaderSize` bytes are skipped at the start of a
//!   separate data file; -1 means "the data is the end of the file".
//! - `MET_LONG`/`MET_ULONG` are 4 bytes in MetaIO.

use std::{
    io::{BufRead, BufReader, Read, Seek, SeekFrom, Write},
    path::{Path, PathBuf},
};

use glam::{DMat3, DVec3};

use super::{
    Format, Loaded, Meta, at,
    raw::{self, Avail, Endian, Scalar, Voxel},
    sibling,
};
use voyage_core::{Error, Result, Volume};

/// Loads a .mha or .mhd (+ data file) as an `i16` volume in LPS.
pub fn load(path: &Path) -> Result<Loaded> {
    let (mut r, len) = raw::open_nonempty(path)?;
    let mut lines = raw::HeaderLines::new(path, &mut r);
    let h = Header::read(path, &mut lines)?;
    let consumed = lines.consumed;
    let fmt = |m: String| Error::format(path, m);

    let (dims, n) = raw::dims3(path, &h.dim_size)?;
    let ty = h
        .element_type
        .ok_or_else(|| fmt("ElementType is missing".into()))?;
    let endian = if h.msb { Endian::Big } else { Endian::Little };
    let expected = (n as u64).saturating_mul(ty.size() as u64);
    let (geom, mut notes) = h.geometry(path, dims)?;

    let data_file = h
        .data_file
        .as_deref()
        .ok_or_else(|| fmt("ElementDataFile is missing".into()))?;
    let decoded = if data_file.eq_ignore_ascii_case("LOCAL") {
        let avail = h.avail(len.saturating_sub(consumed));
        avail.check(path, 0, expected)?;
        h.decode(path, &mut r, n, ty, endian)?
    } else {
        let data_path = data_path(path, data_file)?;
        let (mut dr, data_len) = open_data(path, &data_path)?;
        let offset = h.data_offset(path, data_len, expected)?;
        (|| {
            h.avail(data_len).check(&data_path, offset, expected)?;
            dr.seek(SeekFrom::Start(offset))
                .map_err(|e| Error::io(&data_path, e))?;
            h.decode(&data_path, &mut dr, n, ty, endian)
        })()
        .map_err(raw::in_data_file(path, &data_path))?
    };
    notes.extend(decoded.notes());
    let volume = Volume::from_vec(geom, decoded.voxels).map_err(at(path))?;
    let files = if data_file.eq_ignore_ascii_case("LOCAL") {
        1
    } else {
        2
    };
    let meta = Meta {
        format: Some(Format::MetaImage),
        files,
        modality: h.modality,
        notes,
        ..Meta::default()
    };
    Ok(Loaded { volume, meta })
}

/// The header fields voyage uses.
#[derive(Debug, Default)]
struct Header {
    ndims: Option<usize>,
    dim_size: Vec<u64>,
    spacing: Option<Vec<f64>>,
    element_size: Option<Vec<f64>>,
    offset: Option<Vec<f64>>,
    matrix: Option<Vec<f64>>,
    element_type: Option<Scalar>,
    msb: bool,
    compressed: bool,
    compressed_size: Option<u64>,
    header_size: i64,
    data_file: Option<String>,
    modality: Option<String>,
}

impl Header {
    /// Reads `Key = Value` lines up to and including `ElementDataFile`, which ends the header.
    fn read(path: &Path, lines: &mut raw::HeaderLines) -> Result<Header> {
        let mut h = Header::default();
        let mut any = false;
        let not_text = |e: Error| match e {
            Error::Format { msg, .. } => {
                Error::format(path, format!("not a MetaImage file: {msg}"))
            }
            other => other,
        };
        while let Some(line) = lines.next_line().map_err(not_text)? {
            let line = line.trim();
            if line.is_empty() {
                continue;
            }
            let Some((key, value)) = line.split_once('=') else {
                return Err(Error::format(
                    path,
                    format!("not a MetaImage header line: \"{}\"", raw::clip(line)),
                ));
            };
            any = true;
            let (key, value) = (key.trim(), value.trim());
            h.set(key, value).map_err(|m| Error::format(path, m))?;
            if key.eq_ignore_ascii_case("ElementDataFile") {
                return Ok(h);
            }
        }
        let what = if any {
            "header ends without ElementDataFile"
        } else {
            "not a MetaImage header"
        };
        Err(Error::format(path, what))
    }

    /// Stores one field; unknown keys are ignored.
    fn set(&mut self, key: &str, value: &str) -> Result<(), String> {
        match key.to_ascii_lowercase().as_str() {
            "ndims" => {
                let n = raw::numbers::<usize>(key, value, 1)?[0];
                if n != 3 {
                    return Err(format!("NDims = {n}: voyage reads 3D images only"));
                }
                self.ndims = Some(n);
            }
            "dimsize" => self.dim_size = raw::numbers(key, value, 3)?,
            "elementspacing" => self.spacing = Some(raw::numbers(key, value, 3)?),
            "elementsize" => self.element_size = Some(raw::numbers(key, value, 3)?),
            "offset" | "origin" | "position" => self.offset = Some(raw::numbers(key, value, 3)?),
            "transformmatrix" | "rotation" | "orientation" => {
                self.matrix = Some(raw::numbers(key, value, 9)?)
            }
            "elementtype" => self.element_type = Some(element_type(value)?),
            "binarydatabyteordermsb" | "elementbyteordermsb" => self.msb = boolean(key, value)?,
            "compresseddata" => self.compressed = boolean(key, value)?,
            "compresseddatasize" => self.compressed_size = Some(raw::numbers(key, value, 1)?[0]),
            "headersize" => {
                self.header_size = raw::numbers::<i64>(key, value, 1)?[0];
                if self.header_size < -1 {
                    return Err(format!(
                        "HeaderSize = {}: must be -1 or more",
                        self.header_size
                    ));
                }
            }
            "binarydata" if !boolean(key, value)? => {
                return Err("BinaryData = False (ASCII voxels) is not supported".into());
            }
            "elementnumberofchannels" => {
                let c = raw::numbers::<u64>(key, value, 1)?[0];
                if c != 1 {
                    return Err(format!(
                        "ElementNumberOfChannels = {c}: only scalar images are supported"
                    ));
                }
            }
            "objecttype" if !value.eq_ignore_ascii_case("Image") => {
                return Err(format!("ObjectType = {value}: only Image is supported"));
            }
            "modality" => {
                let m = value.trim_start_matches("MET_MOD_");
                self.modality =
                    (!m.eq_ignore_ascii_case("UNKNOWN") && !m.is_empty()).then(|| m.to_string());
            }
            "elementdatafile" => self.data_file = Some(value.to_string()),
            _ => {}
        }
        Ok(())
    }

    /// Spacing, origin and direction; MetaImage is LPS already.
    fn geometry(
        &self,
        path: &Path,
        dims: [usize; 3],
    ) -> Result<(voyage_core::Geometry, Vec<String>)> {
        if self.ndims.is_none() {
            return Err(Error::format(path, "NDims is missing"));
        }
        let mut notes = Vec::new();
        let spacing = match (&self.spacing, &self.element_size) {
            (Some(s), _) | (None, Some(s)) => DVec3::new(s[0], s[1], s[2]),
            (None, None) => {
                notes.push("no ElementSpacing: 1 mm assumed".to_string());
                DVec3::ONE
            }
        };
        let origin = self
            .offset
            .as_ref()
            .map_or(DVec3::ZERO, |o| DVec3::new(o[0], o[1], o[2]));
        let dir = match &self.matrix {
            None => DMat3::IDENTITY,
            Some(m) => {
                let axes = [0, 3, 6].map(|c| DVec3::new(m[c], m[c + 1], m[c + 2]));
                raw::direction_from_axes(axes)
                    .map_err(|e| Error::format(path, format!("TransformMatrix: {e}")))?
                    .1
            }
        };
        Ok((raw::geometry(path, dims, spacing, origin, dir)?, notes))
    }

    /// How much voxel data a stream of `len` bytes can hold.
    fn avail(&self, len: u64) -> Avail {
        if self.compressed {
            let c = self.compressed_size.map_or(len, |s| s.min(len));
            Avail::AtMost(raw::max_inflated_len(c))
        } else {
            Avail::Exact(len)
        }
    }

    /// Where the voxels start in a separate data file of `len` bytes.
    fn data_offset(&self, path: &Path, len: u64, expected: u64) -> Result<u64> {
        match self.header_size {
            -1 if self.compressed => Err(Error::format(
                path,
                "HeaderSize = -1 cannot be used with compressed data",
            )),
            -1 => Ok(len.saturating_sub(expected)),
            h => Ok(h as u64),
        }
    }

    /// Decodes the voxels from `r`, decompressing when `CompressedData` says so.
    fn decode(
        &self,
        path: &Path,
        r: &mut dyn BufRead,
        n: usize,
        ty: Scalar,
        endian: Endian,
    ) -> Result<raw::Decoded> {
        if !self.compressed {
            return raw::read_voxels(path, r, n, ty, endian, None);
        }
        let limit = self.compressed_size.unwrap_or(u64::MAX);
        let mut limited = r.take(limit);
        let head = limited.fill_buf().map_err(|e| Error::io(path, e))?;
        let mut d: Box<dyn Read> = if raw::is_gzip(head) {
            Box::new(flate2::bufread::MultiGzDecoder::new(limited))
        } else {
            Box::new(flate2::bufread::ZlibDecoder::new(limited))
        };
        let decoded = raw::read_voxels(path, &mut d, n, ty, endian, None)?;
        raw::finish_compressed(path, &mut d)?;
        Ok(decoded)
    }
}

/// Resolves `ElementDataFile` beside the header; file lists and patterns are refused.
fn data_path(header: &Path, name: &str) -> Result<PathBuf> {
    if name.eq_ignore_ascii_case("LIST")
        || name.contains('%')
        || name.split_whitespace().count() > 1
    {
        return Err(Error::format(
            header,
            format!(
                "ElementDataFile = {name}: lists of slice files are not supported, only LOCAL or one file"
            ),
        ));
    }
    crate::detached_data(header, name, "ElementDataFile =")
}

/// Opens the separate data file; a missing file is reported against the header that names it.
fn open_data(header: &Path, data: &Path) -> Result<(BufReader<std::fs::File>, u64)> {
    let opened = std::fs::File::open(data).and_then(|f| f.metadata().map(|m| (f, m.len())));
    match opened {
        Ok((f, len)) => Ok((BufReader::with_capacity(1 << 16, f), len)),
        Err(e) => Err(Error::format(
            header,
            format!(
                "cannot open the data file {} named by ElementDataFile: {e}",
                data.display()
            ),
        )),
    }
}

fn element_type(value: &str) -> Result<Scalar, String> {
    Ok(match value.to_ascii_uppercase().as_str() {
        "MET_UCHAR" => Scalar::U8,
        "MET_CHAR" => Scalar::I8,
        "MET_SHORT" => Scalar::I16,
        "MET_USHORT" => Scalar::U16,
        "MET_INT" | "MET_LONG" => Scalar::I32,
        "MET_UINT" | "MET_ULONG" => Scalar::U32,
        "MET_FLOAT" => Scalar::F32,
        "MET_DOUBLE" => Scalar::F64,
        _ => {
            return Err(format!(
                "ElementType = {value} is not supported (MET_UCHAR ... MET_DOUBLE, scalar)"
            ));
        }
    })
}

fn boolean(key: &str, value: &str) -> Result<bool, String> {
    match value.to_ascii_lowercase().as_str() {
        "true" | "1" | "yes" => Ok(true),
        "false" | "0" | "no" => Ok(false),
        _ => Err(format!("{key} = {value}: expected True or False")),
    }
}

// ---------------------------------------------------------------------------------------
// Writing

/// Saves an `i16` volume: a .mha gets the voxels inline, zlib-compressed; a .mhd gets an
/// uncompressed `<stem>.raw` beside it. Both writes are atomic (data file first).
pub fn save(path: &Path, vol: &Volume<i16>) -> Result<()> {
    let detached = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mhd"));
    if detached {
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let raw_name = format!("{stem}.raw");
        let raw_path = sibling(path, &raw_name);
        super::atomic::write_atomic(&raw_path, |w| write_le(w, vol.data()))?;
        let header = header_text(vol, &raw_name, None);
        super::atomic::write_atomic(path, |w| w.write_all(header.as_bytes()))
    } else {
        let mut enc = flate2::write::ZlibEncoder::new(
            Vec::new(),
            flate2::Compression::new(super::nifti::GZIP_LEVEL),
        );
        write_le(&mut enc, vol.data()).map_err(|e| Error::io(path, e))?;
        let data = enc.finish().map_err(|e| Error::io(path, e))?;
        let header = header_text(vol, "LOCAL", Some(data.len()));
        super::atomic::write_atomic(path, |w| {
            w.write_all(header.as_bytes())?;
            w.write_all(&data)
        })
    }
}

/// The text header; `compressed_size` is Some for zlib data.
fn header_text(vol: &Volume<i16>, data_file: &str, compressed_size: Option<usize>) -> String {
    let g = vol.geometry();
    let d = &g.direction;
    let join = |v: &[f64]| {
        v.iter()
            .map(|x| x.to_string())
            .collect::<Vec<_>>()
            .join(" ")
    };
    let columns: Vec<f64> = (0..3).flat_map(|c| (0..3).map(move |r| d[r][c])).collect();
    let mut s = String::new();
    s += "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n";
    match compressed_size {
        Some(n) => s += &format!("CompressedData = True\nCompressedDataSize = {n}\n"),
        None => s += "CompressedData = False\n",
    }
    s += &format!("TransformMatrix = {}\n", join(&columns));
    s += &format!("Offset = {}\n", join(&g.origin));
    s += "CenterOfRotation = 0 0 0\n";
    s += &format!("ElementSpacing = {}\n", join(&g.spacing));
    s += &format!("DimSize = {} {} {}\n", g.dims[0], g.dims[1], g.dims[2]);
    s += &format!("ElementType = MET_SHORT\nElementDataFile = {data_file}\n");
    s
}

/// Voxels as little-endian bytes, in bounded chunks.
fn write_le(w: &mut dyn Write, data: &[i16]) -> std::io::Result<()> {
    let mut buf = Vec::with_capacity(1 << 20);
    for chunk in data.chunks(1 << 19) {
        buf.clear();
        i16::extend_le(chunk, &mut buf);
        w.write_all(&buf)?;
    }
    Ok(())
}
