//! NRRD (teem): .nrrd with the data after the header's blank line, or a .nhdr header whose
//! `data file:` names the data, relative to the header's folder.
//!
//! Conventions:
//! - `space directions` are the full steps (spacing × unit direction) of the i, j, k axes in
//!   the named `space`; `space origin` is the centre of the first sample. Both are converted
//!   to LPS: right-anterior-superior (RAS) negates x and y, left-anterior-superior (LAS)
//!   negates y. A `space dimension: 3` with no named space is taken as LPS (with a note).
//! - Without `space directions`, `spacings` give the spacing and the axes are taken as LPS.
//! - Encodings: raw and gzip (`gz`); `byte skip` (≥ 0, or -1 for raw data at the end of
//!   the file) and `line skip` are honoured. A missing `endian` is taken as little (noted).
//! - Unknown fields, key/value pairs (`key:=value`) and comments are ignored.

use std::{
    io::{BufRead, BufReader, Write},
    path::{Path, PathBuf},
};

use glam::{DMat3, DVec3};

use super::{
    Format, Loaded, Meta, at,
    raw::{self, Avail, Endian, Scalar, Voxel},
    sibling,
};
use voyage_core::{Error, Geometry, Result, Volume};

/// Loads a .nrrd or .nhdr (+ data file) as an `i16` volume in LPS.
pub fn load(path: &Path) -> Result<Loaded> {
    let (mut r, len) = raw::open_nonempty(path)?;
    let mut lines = raw::HeaderLines::new(path, &mut r);
    let h = Header::read(path, &mut lines)?;
    let consumed = lines.consumed;

    let (dims, n) = raw::dims3(path, &h.sizes)?;
    let ty =
        h.ty.ok_or_else(|| Error::format(path, "the type: field is missing"))?;
    let encoding = h
        .encoding
        .ok_or_else(|| Error::format(path, "the encoding: field is missing"))?;
    let (geom, mut notes) = h.geometry(path, dims)?;
    let endian = h.endian.unwrap_or_else(|| {
        if ty.size() > 1 {
            notes.push("no endian field: little endian assumed".into());
        }
        Endian::Little
    });

    let decoded = match &h.data_file {
        None if !h.ended_by_blank_line => {
            return Err(Error::format(path, "header ends without data"));
        }
        None => h.decode(
            path,
            &mut r,
            len.saturating_sub(consumed),
            (n, ty, endian, encoding),
        )?,
        Some(name) => {
            let data_path = data_path(path, name)?;
            let (mut dr, data_len) = open_data(path, &data_path)?;
            h.decode(&data_path, &mut dr, data_len, (n, ty, endian, encoding))
                .map_err(raw::in_data_file(path, &data_path))?
        }
    };
    notes.extend(decoded.notes());
    let volume = Volume::from_vec(geom, decoded.voxels).map_err(at(path))?;
    let files = if h.data_file.is_some() { 2 } else { 1 };
    let meta = Meta {
        format: Some(Format::Nrrd),
        files,
        notes,
        ..Meta::default()
    };
    Ok(Loaded { volume, meta })
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Encoding {
    Raw,
    Gzip,
}

/// The named patient space of the header, as a map to LPS.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Space {
    Lps,
    Ras,
    Las,
    /// `space dimension: 3` without a name.
    Unnamed,
}

impl Space {
    /// Multiplies a vector in this space to get LPS.
    fn to_lps(self) -> DMat3 {
        match self {
            Space::Lps | Space::Unnamed => DMat3::IDENTITY,
            Space::Ras => DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0)),
            Space::Las => DMat3::from_diagonal(DVec3::new(1.0, -1.0, 1.0)),
        }
    }
}

/// The header fields voyage uses.
#[derive(Debug, Default)]
struct Header {
    ty: Option<Scalar>,
    dimension: Option<usize>,
    sizes: Vec<u64>,
    space: Option<Space>,
    directions: Option<[DVec3; 3]>,
    origin: Option<DVec3>,
    spacings: Option<Vec<f64>>,
    endian: Option<Endian>,
    encoding: Option<Encoding>,
    data_file: Option<String>,
    byte_skip: i64,
    line_skip: u64,
    /// Whether the header ended with a blank line (then attached data follows).
    ended_by_blank_line: bool,
}

/// What to decode: voxel count, element type, byte order, encoding.
type Layout = (usize, Scalar, Endian, Encoding);

impl Header {
    /// Reads the magic line, then fields up to a blank line or the end of the file.
    fn read(path: &Path, lines: &mut raw::HeaderLines) -> Result<Header> {
        match lines.next_line() {
            Ok(Some(magic)) if magic.starts_with("NRRD") => {}
            Ok(_) | Err(Error::Format { .. }) => {
                return Err(Error::format(path, "not a NRRD file (no \"NRRD\" magic)"));
            }
            Err(e) => return Err(e),
        }
        let mut h = Header::default();
        while let Some(line) = lines.next_line()? {
            if line.trim().is_empty() {
                h.ended_by_blank_line = true;
                break;
            }
            if line.starts_with('#') || line.contains(":=") {
                continue;
            }
            let Some((field, value)) = line.split_once(": ") else {
                return Err(Error::format(
                    path,
                    format!("not a NRRD field line: \"{}\"", raw::clip(&line)),
                ));
            };
            h.set(&field.trim().to_ascii_lowercase(), value.trim())
                .map_err(|m| Error::format(path, m))?;
        }
        Ok(h)
    }

    /// Stores one field; unknown fields are ignored.
    fn set(&mut self, field: &str, value: &str) -> Result<(), String> {
        match field {
            "type" => self.ty = Some(scalar(value)?),
            "dimension" => {
                let d = raw::numbers::<usize>(field, value, 1)?[0];
                if d != 3 {
                    return Err(format!("dimension: {d}: voyage reads 3D volumes only"));
                }
                self.dimension = Some(d);
            }
            "sizes" => self.sizes = raw::numbers(field, value, 3)?,
            "space" => self.space = Some(space(value)?),
            "space dimension" => {
                let d = raw::numbers::<usize>(field, value, 1)?[0];
                if d != 3 {
                    return Err(format!(
                        "space dimension: {d}: only 3D spaces are supported"
                    ));
                }
                self.space.get_or_insert(Space::Unnamed);
            }
            "space directions" => {
                let v = vectors(field, value)?;
                let axes: [DVec3; 3] = v
                    .try_into()
                    .map_err(|_| format!("space directions: expected 3 vectors in \"{value}\""))?;
                self.directions = Some(axes);
            }
            "space origin" => {
                let v = vectors(field, value)?;
                match v.as_slice() {
                    [o] => self.origin = Some(*o),
                    _ => return Err(format!("space origin: expected one vector in \"{value}\"")),
                }
            }
            "spacings" => self.spacings = Some(raw::numbers(field, value, 3)?),
            "endian" => {
                self.endian = Some(match value {
                    "little" => Endian::Little,
                    "big" => Endian::Big,
                    _ => return Err(format!("endian: {value}: expected little or big")),
                })
            }
            "encoding" => {
                self.encoding = Some(match value {
                    "raw" => Encoding::Raw,
                    "gzip" | "gz" => Encoding::Gzip,
                    _ => return Err(format!("encoding: {value} is not supported (raw, gzip)")),
                })
            }
            "data file" | "datafile" => self.data_file = Some(value.to_string()),
            "byte skip" | "byteskip" => {
                self.byte_skip = raw::numbers::<i64>(field, value, 1)?[0];
                if self.byte_skip < -1 {
                    return Err(format!("byte skip: {}: must be -1 or more", self.byte_skip));
                }
            }
            "line skip" | "lineskip" => self.line_skip = raw::numbers(field, value, 1)?[0],
            _ => {}
        }
        Ok(())
    }

    /// Spacing, origin and direction, converted to LPS.
    fn geometry(&self, path: &Path, dims: [usize; 3]) -> Result<(Geometry, Vec<String>)> {
        if self.dimension.is_none() {
            return Err(Error::format(path, "the dimension: field is missing"));
        }
        let mut notes = Vec::new();
        let space = self.space.unwrap_or(Space::Unnamed);
        if self.space == Some(Space::Unnamed) {
            notes.push("space has no name: taken as LPS".to_string());
        }
        let to_lps = space.to_lps();
        let (spacing, dir) = match (&self.directions, &self.spacings) {
            (Some(axes), _) => raw::direction_from_axes(axes.map(|a| to_lps * a))
                .map_err(|m| Error::format(path, format!("space directions: {m}")))?,
            (None, Some(s)) => {
                notes.push("no space directions: axes taken as LPS".to_string());
                (DVec3::new(s[0], s[1], s[2]), DMat3::IDENTITY)
            }
            (None, None) => {
                notes.push("no space directions or spacings: 1 mm assumed".to_string());
                (DVec3::ONE, DMat3::IDENTITY)
            }
        };
        let origin = self.origin.map_or(DVec3::ZERO, |o| to_lps * o);
        Ok((raw::geometry(path, dims, spacing, origin, dir)?, notes))
    }

    /// Skips `line skip` lines and `byte skip` bytes, then decodes the voxels from `r`, a
    /// stream with `len` bytes left.
    fn decode(
        &self,
        path: &Path,
        r: &mut dyn BufRead,
        len: u64,
        layout: Layout,
    ) -> Result<raw::Decoded> {
        let (n, ty, endian, encoding) = layout;
        let expected = (n as u64).saturating_mul(ty.size() as u64);
        let mut skipped = 0u64;
        for _ in 0..self.line_skip {
            let mut line = Vec::new();
            let k = r
                .read_until(b'\n', &mut line)
                .map_err(|e| Error::io(path, e))?;
            if k == 0 {
                return Err(Error::format(
                    path,
                    format!("line skip: {}: the data has fewer lines", self.line_skip),
                ));
            }
            skipped += k as u64;
        }
        let left = len.saturating_sub(skipped);
        match encoding {
            Encoding::Raw => {
                let offset = match self.byte_skip {
                    -1 => left.saturating_sub(expected),
                    b => b as u64,
                };
                Avail::Exact(left).check(path, offset, expected)?;
                raw::skip(r, offset)
                    .map_err(|e| raw::read_error(path, e))?
                    .check(path, offset)?;
                raw::read_voxels(path, r, n, ty, endian, None)
            }
            Encoding::Gzip => {
                if self.byte_skip < 0 {
                    return Err(Error::format(
                        path,
                        "byte skip: -1 is only allowed with raw encoding",
                    ));
                }
                let offset = self.byte_skip as u64;
                Avail::AtMost(raw::max_inflated_len(left)).check(path, offset, expected)?;
                let mut d = flate2::bufread::MultiGzDecoder::new(r);
                raw::skip(&mut d, offset)
                    .map_err(|e| raw::read_error(path, e))?
                    .check(path, offset)?;
                let decoded = raw::read_voxels(path, &mut d, n, ty, endian, None)?;
                raw::finish_compressed(path, &mut d)?;
                Ok(decoded)
            }
        }
    }
}

/// The element type from teem's names for it.
fn scalar(value: &str) -> Result<Scalar, String> {
    Ok(match value.to_ascii_lowercase().as_str() {
        "signed char" | "int8" | "int8_t" => Scalar::I8,
        "uchar" | "unsigned char" | "uint8" | "uint8_t" => Scalar::U8,
        "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => {
            Scalar::I16
        }
        "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => Scalar::U16,
        "int" | "signed int" | "int32" | "int32_t" => Scalar::I32,
        "uint" | "unsigned int" | "uint32" | "uint32_t" => Scalar::U32,
        "float" => Scalar::F32,
        "double" => Scalar::F64,
        _ => {
            return Err(format!(
                "type: {value} is not supported (8 to 32-bit integers, float, double)"
            ));
        }
    })
}

fn space(value: &str) -> Result<Space, String> {
    Ok(match value.to_ascii_lowercase().as_str() {
        "left-posterior-superior" | "lps" => Space::Lps,
        "right-anterior-superior" | "ras" => Space::Ras,
        "left-anterior-superior" | "las" => Space::Las,
        _ => return Err(format!("space: {value} is not supported (LPS, RAS, LAS)")),
    })
}

/// Parses "(x,y,z) (x,y,z) ..." vectors; "none" (a non-spatial axis) is refused, since
/// voyage reads three spatial axes.
fn vectors(field: &str, value: &str) -> Result<Vec<DVec3>, String> {
    let mut out = Vec::new();
    let mut rest = value.trim();
    while !rest.is_empty() {
        let Some(inner) = rest.strip_prefix('(') else {
            return Err(format!(
                "{field}: expected \"(x,y,z)\" vectors in \"{}\"",
                raw::clip(value)
            ));
        };
        let Some((inside, after)) = inner.split_once(')') else {
            return Err(format!(
                "{field}: unclosed parenthesis in \"{}\"",
                raw::clip(value)
            ));
        };
        let v: Vec<f64> = inside
            .split(',')
            .map(|t| t.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| format!("{field}: cannot read numbers from \"({inside})\""))?;
        match v.as_slice() {
            [x, y, z] => out.push(DVec3::new(*x, *y, *z)),
            _ => return Err(format!("{field}: expected 3 components in \"({inside})\"")),
        }
        rest = after.trim_start();
    }
    Ok(out)
}

/// Resolves `data file:` beside the header; file lists and patterns are refused.
fn data_path(header: &Path, name: &str) -> Result<PathBuf> {
    if name == "LIST" || name.contains('%') || name.split_whitespace().count() > 1 {
        return Err(Error::format(
            header,
            format!("data file: {name}: lists of data files are not supported, only one file"),
        ));
    }
    crate::detached_data(header, name, "data file:")
}

/// Opens the data file; a missing file is reported against the header that names it.
fn open_data(header: &Path, data: &Path) -> Result<(BufReader<std::fs::File>, u64)> {
    let opened = std::fs::File::open(data).and_then(|f| f.metadata().map(|m| (f, m.len())));
    match opened {
        Ok((f, len)) => Ok((BufReader::with_capacity(1 << 16, f), len)),
        Err(e) => Err(Error::format(
            header,
            format!(
                "cannot open the data file {} named by data file: {e}",
                data.display()
            ),
        )),
    }
}

// ---------------------------------------------------------------------------------------
// Writing

/// Saves an `i16` volume, gzip-compressed, in LPS: a .nrrd holds the data after its
/// header; a .nhdr names a `<stem>.raw.gz` beside it. Atomic (data file first).
pub fn save(path: &Path, vol: &Volume<i16>) -> Result<()> {
    let detached = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("nhdr"));
    if detached {
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let data_name = format!("{stem}.raw.gz");
        super::atomic::write_atomic(&sibling(path, &data_name), |w| write_gzip(w, vol.data()))?;
        let header = header_text(vol.geometry(), Some(&data_name));
        super::atomic::write_atomic(path, |w| w.write_all(header.as_bytes()))
    } else {
        let header = header_text(vol.geometry(), None);
        super::atomic::write_atomic(path, |w| {
            w.write_all(header.as_bytes())?;
            write_gzip(w, vol.data())
        })
    }
}

/// The text header, ending in a blank line when the data is attached.
fn header_text(g: &Geometry, data_file: Option<&str>) -> String {
    let vec = |v: DVec3| format!("({},{},{})", v.x, v.y, v.z);
    let m = g.direction_mat();
    let axes = [
        m.x_axis * g.spacing[0],
        m.y_axis * g.spacing[1],
        m.z_axis * g.spacing[2],
    ];
    let mut s = String::from("NRRD0004\n# Complete NRRD file format specification at:\n");
    s += "# http://teem.sourceforge.net/nrrd/format.html\n";
    s += "type: short\ndimension: 3\nspace: left-posterior-superior\n";
    s += &format!("sizes: {} {} {}\n", g.dims[0], g.dims[1], g.dims[2]);
    s += &format!(
        "space directions: {} {} {}\n",
        vec(axes[0]),
        vec(axes[1]),
        vec(axes[2])
    );
    s += "kinds: domain domain domain\nendian: little\nencoding: gzip\n";
    s += &format!("space origin: {}\n", vec(DVec3::from_array(g.origin)));
    match data_file {
        Some(name) => s += &format!("data file: {name}\n"),
        None => s += "\n",
    }
    s
}

/// Voxels as little-endian bytes through a fast gzip encoder.
fn write_gzip(w: &mut dyn Write, data: &[i16]) -> std::io::Result<()> {
    let mut enc =
        flate2::write::GzEncoder::new(w, flate2::Compression::new(super::nifti::GZIP_LEVEL));
    let mut buf = Vec::with_capacity(1 << 20);
    for chunk in data.chunks(1 << 19) {
        buf.clear();
        i16::extend_le(chunk, &mut buf);
        enc.write_all(&buf)?;
    }
    enc.finish()?;
    Ok(())
}
