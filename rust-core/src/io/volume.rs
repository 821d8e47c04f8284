//! Regular volume readers: VTK ImageData (`.vti`), NRRD (`.nrrd`, raw or gzip encoding,
//! data attached), NumPy (`.npy`, a 3-D array in C order, x fastest) and headerless raw
//! files with given dimensions and element type. Values keep their type when it is f32,
//! u16 or u8; other numeric types are converted to f32.

use super::numeric::{show, Endian, Scalar};
use crate::error::{Error, Result};
use crate::field::grid::{Lattice, Narrowing, Values, Volume};
use glam::DVec3;
use std::io::Read;
use std::path::Path;

/// Extensions [`read_volume`] understands (`.raw` needs a [`RawLayout`]).
pub const VOLUME_EXTENSIONS: &[&str] = &["vti", "nrrd", "npy", "raw"];

/// How a headerless raw file is laid out.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RawLayout {
    /// Nodes per axis, x fastest.
    pub dims: [usize; 3],
    /// Element type: "u8", "u16", "i16", "f32", "f64" ...
    pub ty: RawType,
    pub big_endian: bool,
    pub origin: DVec3,
    pub spacing: DVec3,
}

/// Element type of a raw file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RawType {
    U8,
    I8,
    U16,
    I16,
    U32,
    I32,
    F32,
    F64,
}

impl std::str::FromStr for RawType {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Ok(match s.to_ascii_lowercase().as_str() {
            "u8" | "uint8" | "uchar" => RawType::U8,
            "i8" | "int8" | "char" => RawType::I8,
            "u16" | "uint16" | "ushort" => RawType::U16,
            "i16" | "int16" | "short" => RawType::I16,
            "u32" | "uint32" | "uint" => RawType::U32,
            "i32" | "int32" | "int" => RawType::I32,
            "f32" | "float32" | "float" => RawType::F32,
            "f64" | "float64" | "double" => RawType::F64,
            other => {
                return Err(Error::InvalidParameter {
                    name: "raw type",
                    message: format!(
                        "unknown element type '{other}' (u8 i8 u16 i16 u32 i32 f32 f64)"
                    ),
                })
            }
        })
    }
}

impl RawType {
    fn scalar(self) -> Scalar {
        match self {
            RawType::U8 => Scalar::U8,
            RawType::I8 => Scalar::I8,
            RawType::U16 => Scalar::U16,
            RawType::I16 => Scalar::I16,
            RawType::U32 => Scalar::U32,
            RawType::I32 => Scalar::I32,
            RawType::F32 => Scalar::F32,
            RawType::F64 => Scalar::F64,
        }
    }
}

/// Reads a volume, choosing the format by extension. `array` names the ImageData point
/// array to use; `raw` is required for `.raw` files.
pub fn read_volume(path: &Path, array: Option<&str>, raw: Option<RawLayout>) -> Result<Volume> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let name = path.display().to_string();
    if !VOLUME_EXTENSIONS.contains(&ext.as_str()) {
        return Err(Error::format(
            path,
            format!(
                "unknown volume format '.{ext}' (supported: {})",
                VOLUME_EXTENSIONS.join(", ")
            ),
        ));
    }
    if ext == "raw" && raw.is_none() {
        return Err(Error::format(
            path,
            "a .raw volume needs its dimensions and element type (--raw-dims, --raw-type)",
        ));
    }
    let bytes = super::read_regular_file(path)?;
    match ext.as_str() {
        "vti" => read_vti(&bytes, &name, array),
        "nrrd" => read_nrrd(&bytes, &name),
        "npy" => {
            let (dims, ty, endian, data) = super::npy::read_npy_volume(&bytes, &name)?;
            build(
                &name,
                dims,
                DVec3::ZERO,
                DVec3::ONE,
                decode(ty, data, endian),
            )
        }
        _ => read_raw(&bytes, &name, raw.unwrap_or(RawLayout::default_for(&name))),
    }
}

impl RawLayout {
    /// Placeholder never used for reading (read_volume checks first).
    fn default_for(_: &str) -> Self {
        RawLayout {
            dims: [0; 3],
            ty: RawType::U8,
            big_endian: false,
            origin: DVec3::ZERO,
            spacing: DVec3::ONE,
        }
    }
}

/// A VTK ImageData file in memory.
pub fn read_vti(bytes: &[u8], name: &str, array: Option<&str>) -> Result<Volume> {
    let image = super::vtk_xml::read_image(bytes, name, array)?;
    build(
        name,
        image.dims,
        DVec3::from_array(image.origin),
        DVec3::from_array(image.spacing),
        from_f64(image.ty, &image.values),
    )
    .map_err(|e| match e {
        Error::InvalidInput(m) => Error::format(name, format!("array '{}': {m}", image.array)),
        e => e,
    })
}

/// A headerless raw file in memory; its size must match the layout exactly.
pub fn read_raw(bytes: &[u8], name: &str, layout: RawLayout) -> Result<Volume> {
    let ty = layout.ty.scalar();
    let count = layout
        .dims
        .iter()
        .try_fold(1usize, |a, &d| a.checked_mul(d));
    let need = count.and_then(|c| c.checked_mul(ty.size()));
    if need != Some(bytes.len()) {
        return Err(Error::format(
            name,
            format!(
                "a {}×{}×{} raw volume of {:?} needs {} bytes, the file holds {}",
                layout.dims[0],
                layout.dims[1],
                layout.dims[2],
                layout.ty,
                need.map_or("too many".into(), |n| n.to_string()),
                bytes.len()
            ),
        ));
    }
    let endian = if layout.big_endian {
        Endian::Big
    } else {
        Endian::Little
    };
    build(
        name,
        layout.dims,
        layout.origin,
        layout.spacing,
        decode(ty, bytes, endian),
    )
}

/// A NRRD file with attached data (`raw` or `gzip` encoding).
pub fn read_nrrd(bytes: &[u8], name: &str) -> Result<Volume> {
    let err = |m: String| Error::format(name, m);
    if !bytes.starts_with(b"NRRD000") {
        return Err(err("not a NRRD file (no NRRD000x magic)".into()));
    }
    // The header ends at the first empty line.
    let (header_end, data_start) = match super::vtk_xml::find_bytes(bytes, b"\n\n") {
        Some(i) => (i, i + 2),
        None => match super::vtk_xml::find_bytes(bytes, b"\r\n\r\n") {
            Some(i) => (i, i + 4),
            None => return Err(err("truncated: no empty line ends the header".into())),
        },
    };
    let header = String::from_utf8_lossy(&bytes[..header_end]);
    let mut ty = None;
    let mut dimension = None;
    let mut sizes: Option<Vec<usize>> = None;
    let mut encoding = String::from("raw");
    let mut endian = Endian::Little;
    let mut spacing = DVec3::ONE;
    let mut origin = DVec3::ZERO;
    let mut line_skip = 0usize;
    let mut byte_skip = ByteSkip::Bytes(0);
    for line in header.lines().skip(1) {
        let line = line.trim();
        if line.starts_with('#') || line.is_empty() {
            continue;
        }
        let Some((key, value)) = line.split_once(':') else {
            continue;
        };
        // `key:=value` lines are key/value pairs, not fields.
        if value.starts_with('=') {
            continue;
        }
        let value = value.trim();
        // Teem accepts "byteskip" for "byte skip", "datafile" for "data file" ...
        let field: String = key
            .split_whitespace()
            .collect::<String>()
            .to_ascii_lowercase();
        let bad = |what: &str| err(format!("field '{}': {what}", key.trim()));
        match field.as_str() {
            "type" => {
                ty = Some(nrrd_type(value).ok_or_else(|| {
                    err(format!(
                        "unsupported NRRD type '{}'",
                        show(value.as_bytes())
                    ))
                })?)
            }
            "dimension" => dimension = value.parse::<usize>().ok(),
            "sizes" => {
                sizes = Some(
                    value
                        .split_whitespace()
                        .map(str::parse)
                        .collect::<std::result::Result<_, _>>()
                        .map_err(|_| err(format!("bad sizes '{}'", show(value.as_bytes()))))?,
                )
            }
            "encoding" => encoding = value.to_ascii_lowercase(),
            "endian" => {
                endian = match value.to_ascii_lowercase().as_str() {
                    "little" => Endian::Little,
                    "big" => Endian::Big,
                    _ => {
                        return Err(bad(&format!(
                            "'{}' is neither little nor big",
                            show(value.as_bytes())
                        )))
                    }
                }
            }
            "spacings" => {
                let v = numbers(value).map_err(|m| bad(&m))?;
                spacing = axis_triple(&v).map_err(|m| bad(&m))?;
            }
            "spacedirections" => spacing = direction_lengths(value).map_err(|m| bad(&m))?,
            "spaceorigin" => {
                let v =
                    numbers(value.trim_matches(|c| c == '(' || c == ')')).map_err(|m| bad(&m))?;
                origin = axis_triple(&v).map_err(|m| bad(&m))?;
            }
            "lineskip" => {
                line_skip = value.parse().map_err(|_| {
                    bad(&format!("'{}' is not a line count", show(value.as_bytes())))
                })?
            }
            "byteskip" => {
                byte_skip = match value.parse::<i64>() {
                    Ok(-1) => ByteSkip::ToEnd,
                    Ok(n) if n >= 0 => ByteSkip::Bytes(n as usize),
                    _ => {
                        return Err(bad(&format!(
                            "'{}' is neither a byte count nor -1",
                            show(value.as_bytes())
                        )))
                    }
                }
            }
            "datafile" => {
                return Err(err(
                    "detached data files are not supported; save the NRRD with attached data"
                        .into(),
                ))
            }
            _ => {}
        }
    }
    let ty = ty.ok_or_else(|| err("no 'type' field".into()))?;
    if dimension != Some(3) {
        return Err(err(format!(
            "a volume needs 'dimension: 3', got {}",
            dimension.map_or("none".into(), |d| d.to_string())
        )));
    }
    let sizes = sizes.ok_or_else(|| err("no 'sizes' field".into()))?;
    let [nx, ny, nz] = sizes[..] else {
        return Err(err(format!(
            "'sizes' has {} entries, expected 3",
            sizes.len()
        )));
    };
    let count = nx
        .checked_mul(ny)
        .and_then(|n| n.checked_mul(nz))
        .and_then(|n| n.checked_mul(ty.size()))
        .ok_or_else(|| err("sizes are impossibly large".into()))?;
    // "line skip" lines, then "byte skip" bytes, come before the data: the skipped lines
    // in the file as stored, the skipped bytes in the decoded data (NRRD's order).
    let mut payload = &bytes[data_start..];
    for skipped in 0..line_skip {
        let Some(end) = payload.iter().position(|&b| b == b'\n') else {
            return Err(err(format!(
                "truncated: 'line skip: {line_skip}' passes the end of the file after {skipped} lines"
            )));
        };
        payload = &payload[end + 1..];
    }
    let (data, skip): (std::borrow::Cow<[u8]>, usize) = match encoding.as_str() {
        "raw" => match byte_skip {
            // -1: the data is the file's last bytes.
            ByteSkip::ToEnd => (payload[payload.len().saturating_sub(count)..].into(), 0),
            ByteSkip::Bytes(n) => (payload.into(), n),
        },
        "gzip" | "gz" => {
            let ByteSkip::Bytes(skip) = byte_skip else {
                return Err(err(
                    "'byte skip: -1' (data at the end of the file) needs raw encoding".into(),
                ));
            };
            let total = count
                .checked_add(skip)
                .ok_or_else(|| err("'byte skip' is impossibly large".into()))?;
            (inflate_exactly(payload, total).map_err(err)?.into(), skip)
        }
        other => {
            return Err(err(format!(
                "NRRD encoding '{}' is not supported (raw, gzip)",
                show(other.as_bytes())
            )))
        }
    };
    let data = data.get(skip..).unwrap_or_default();
    if data.len() < count {
        return Err(err(format!(
            "truncated: {nx}×{ny}×{nz} values need {count} bytes, the data holds {}{}",
            data.len(),
            if skip > 0 {
                format!(" after 'byte skip: {skip}'")
            } else {
                String::new()
            }
        )));
    }
    let mut volume = build(
        name,
        [nx, ny, nz],
        origin,
        spacing.abs(),
        decode(ty, &data[..count], endian),
    )?;
    // An index that runs against its axis: the same nodes, stored the other way round
    // (a lattice's spacing is positive), so the surface is not mirrored.
    for axis in (0..3).filter(|&a| spacing[a] < 0.0) {
        volume.reverse_axis(axis);
    }
    Ok(volume)
}

/// Where a NRRD's data starts after its skipped lines.
#[derive(Clone, Copy)]
enum ByteSkip {
    Bytes(usize),
    /// `byte skip: -1`: the data ends the file.
    ToEnd,
}

/// The first `total` bytes a gzip stream decodes to (fewer if it holds fewer). The whole
/// stream is read, since the decoder checks a member's CRC-32 only at its end (a flipped
/// bit must not pass as values), but not past `total` + 1 bytes: a stream that holds far
/// more than declared is refused.
fn inflate_exactly(payload: &[u8], total: usize) -> std::result::Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(total.min(payload.len().saturating_mul(16)));
    let mut gz = flate2::read::MultiGzDecoder::new(payload);
    (&mut gz)
        .take(total as u64)
        .read_to_end(&mut out)
        .map_err(|e| format!("gzip data: {e}"))?;
    let limit = total as u64 + 1;
    let beyond = std::io::copy(&mut (&mut gz).take(limit), &mut std::io::sink())
        .map_err(|e| format!("gzip data: {e}"))?;
    if beyond == limit {
        return Err(format!(
            "the gzip data holds more than the {total} bytes its sizes declare"
        ));
    }
    Ok(out)
}

/// Every number in `text` (separated by spaces or commas); any other word is an error,
/// so a field that does not parse is never silently replaced by its default.
fn numbers(text: &str) -> std::result::Result<Vec<f64>, String> {
    text.split(|c: char| c.is_whitespace() || c == ',')
        .filter(|t| !t.is_empty())
        .map(|t| {
            t.parse::<f64>()
                .map_err(|_| format!("'{}' is not a number", show(t.as_bytes())))
        })
        .collect()
}

/// Three finite numbers, one per axis.
fn axis_triple(v: &[f64]) -> std::result::Result<DVec3, String> {
    match v {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(DVec3::new(*x, *y, *z)),
        [_, _, _] => Err(format!("{v:?} is not finite")),
        _ => Err(format!("{} values, expected 3 (one per axis)", v.len())),
    }
}

/// The node spacing from `space directions: (a,0,0) (0,b,0) (0,0,c)`: each vector's
/// signed length (negative: the index runs against the axis, as in LPS scans). Only
/// axis-aligned volumes are supported; a non-spatial axis (`none`) cannot be one of a
/// scalar volume's three.
fn direction_lengths(value: &str) -> std::result::Result<DVec3, String> {
    let mut vectors = Vec::new();
    for (axis, word) in value
        .split(')')
        .map(str::trim)
        .filter(|w| !w.is_empty())
        .enumerate()
    {
        let Some(inside) = word.strip_prefix('(') else {
            return Err(format!(
                "axis {axis} has no direction vector ('{}'): a volume needs three spatial axes",
                show(word.as_bytes())
            ));
        };
        vectors.push(axis_triple(&numbers(inside)?)?);
    }
    if vectors.len() != 3 {
        return Err(format!("{} vectors, expected 3", vectors.len()));
    }
    let mut spacing = DVec3::ZERO;
    for (a, v) in vectors.iter().enumerate() {
        if (0..3).any(|b| b != a && v[b] != 0.0) {
            return Err(
                "the directions are not axis-aligned; only axis-aligned volumes are supported"
                    .into(),
            );
        }
        spacing[a] = v[a];
    }
    Ok(spacing)
}

fn nrrd_type(t: &str) -> Option<Scalar> {
    Some(match t {
        "uchar" | "unsigned char" | "uint8" | "uint8_t" => Scalar::U8,
        "signed char" | "int8" | "int8_t" => Scalar::I8,
        "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => Scalar::U16,
        "short" | "short int" | "signed short" | "int16" | "int16_t" => Scalar::I16,
        "uint" | "unsigned int" | "uint32" | "uint32_t" => Scalar::U32,
        "int" | "signed int" | "int32" | "int32_t" => Scalar::I32,
        "float" => Scalar::F32,
        "double" => Scalar::F64,
        _ => return None,
    })
}

/// Values as read: u8 and u16 kept, types f32 holds exactly (i8, i16, f32) as f32, wider
/// ones (f64, 32- and 64-bit integers) narrowed to f32 with what that loses.
#[derive(Debug)]
enum Decoded {
    Kept(Values),
    Narrowed(Vec<f32>, Narrowing),
}

impl Decoded {
    fn into_volume(self, lattice: Lattice) -> Result<Volume> {
        match self {
            Decoded::Kept(values) => Volume::new(lattice, values),
            Decoded::Narrowed(values, narrowing) => narrowing.finish(lattice, values),
        }
    }

    #[cfg(test)]
    fn values(self) -> Values {
        match self {
            Decoded::Kept(values) => values,
            Decoded::Narrowed(values, _) => Values::F32(values),
        }
    }
}

/// True for element types whose every value f32 holds exactly.
fn exact_in_f32(ty: Scalar) -> bool {
    matches!(
        ty,
        Scalar::U8 | Scalar::I8 | Scalar::U16 | Scalar::I16 | Scalar::F32
    )
}

/// Values decoded from f64s of element type `ty`.
fn from_f64(ty: Scalar, data: &[f64]) -> Decoded {
    match ty {
        Scalar::U8 => Decoded::Kept(Values::U8(data.iter().map(|&v| v as u8).collect())),
        Scalar::U16 => Decoded::Kept(Values::U16(data.iter().map(|&v| v as u16).collect())),
        _ if exact_in_f32(ty) => {
            Decoded::Kept(Values::F32(data.iter().map(|&v| v as f32).collect()))
        }
        _ => {
            let mut narrowing = Narrowing::default();
            let values = data.iter().map(|&v| narrowing.narrow(v)).collect();
            Decoded::Narrowed(values, narrowing)
        }
    }
}

/// Values decoded from `bytes` of element type `ty`, as [`from_f64`] keeps them: a volume
/// is never held as f64s (twice an f32 volume's bytes) on its way in.
fn decode(ty: Scalar, bytes: &[u8], endian: Endian) -> Decoded {
    match ty {
        Scalar::U8 => Decoded::Kept(Values::U8(bytes.to_vec())),
        Scalar::U16 => Decoded::Kept(Values::U16(decode_as(ty, bytes, endian, |x| x as u16))),
        _ if exact_in_f32(ty) => {
            Decoded::Kept(Values::F32(decode_as(ty, bytes, endian, |x| x as f32)))
        }
        _ => {
            let mut narrowing = Narrowing::default();
            let values = decode_as(ty, bytes, endian, |x| narrowing.narrow(x));
            Decoded::Narrowed(values, narrowing)
        }
    }
}

/// `bytes` decoded a bounded slice at a time through f64, each value converted.
fn decode_as<T>(
    ty: Scalar,
    bytes: &[u8],
    endian: Endian,
    mut convert: impl FnMut(f64) -> T,
) -> Vec<T> {
    const SLICE: usize = 1 << 16;
    let mut out = Vec::with_capacity(bytes.len() / ty.size());
    let mut decoded = Vec::with_capacity(SLICE);
    for piece in bytes.chunks(SLICE * ty.size()) {
        decoded.clear();
        ty.decode_into(piece, endian, &mut decoded);
        out.extend(decoded.iter().map(|&x| convert(x)));
    }
    out
}

/// Makes a volume of `values` on a lattice of `dims` nodes.
fn build(
    name: &str,
    dims: [usize; 3],
    origin: DVec3,
    spacing: DVec3,
    values: Decoded,
) -> Result<Volume> {
    let lattice =
        Lattice::new(dims, origin, spacing).map_err(|e| Error::format(name, e.to_string()))?;
    values.into_volume(lattice).map_err(|e| match e {
        Error::InvalidInput(m) => Error::format(name, m),
        e => e,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(dims: [usize; 3]) -> Vec<u16> {
        (0..dims[0] * dims[1] * dims[2])
            .map(|i| (i * 7 % 1000) as u16)
            .collect()
    }

    #[test]
    fn decoding_bytes_keeps_what_decoding_through_f64_keeps() {
        // Past one decoding slice, both byte orders, every kind of element type.
        let n = (1 << 16) + 5;
        for (ty, endian) in [
            (Scalar::U8, Endian::Little),
            (Scalar::I8, Endian::Little),
            (Scalar::U16, Endian::Big),
            (Scalar::I16, Endian::Little),
            (Scalar::I32, Endian::Big),
            (Scalar::F32, Endian::Little),
            (Scalar::F64, Endian::Big),
        ] {
            let bytes: Vec<u8> = (0..n * ty.size()).map(|i| (i * 131 % 256) as u8).collect();
            let through = from_f64(ty, &ty.decode(&bytes, endian)).values();
            assert_eq!(through.len(), n);
            // NaN != NaN: compare bits.
            let bits = |v: &Values| (0..v.len()).map(|i| v.get(i).to_bits()).collect::<Vec<_>>();
            let direct = decode(ty, &bytes, endian).values();
            assert_eq!(direct.value_type(), through.value_type(), "{ty:?}");
            assert!(bits(&direct) == bits(&through), "{ty:?} {endian:?}");
        }
    }

    /// `space directions` whose index runs against an axis (LPS scans write (-1,0,0)):
    /// every value stays where the file puts it, not mirrored about the origin.
    #[test]
    fn a_nrrd_index_running_against_its_axis_keeps_each_value_in_place() {
        let dims = [3, 4, 5];
        let v = ramp(dims);
        let le: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        let head = "NRRD0004\ntype: unsigned short\ndimension: 3\nsizes: 3 4 5\nendian: little\n\
                    space directions: (-0.5,0,0) (0,0.5,0) (0,0,-2)\nspace origin: (1,2,3)\n\
                    encoding: raw\n\n";
        let mut bytes = head.as_bytes().to_vec();
        bytes.extend_from_slice(&le);
        let volume = read_nrrd(&bytes, "lps.nrrd").unwrap();
        assert_eq!(volume.lattice.spacing, DVec3::new(0.5, 0.5, 2.0));
        assert_eq!(volume.lattice.origin, DVec3::new(0.0, 2.0, -5.0));
        for (i, &value) in v.iter().enumerate() {
            let [x, y, z] = [i % 3, (i / 3) % 4, i / 12];
            // Where the file puts node (x, y, z), and the node of the volume there.
            let p = DVec3::new(
                1.0 - 0.5 * x as f64,
                2.0 + 0.5 * y as f64,
                3.0 - 2.0 * z as f64,
            );
            let c = (p - volume.lattice.origin) / volume.lattice.spacing;
            let node = c.round().as_uvec3();
            assert_eq!(
                volume.at(node.x as usize, node.y as usize, node.z as usize),
                value as f32
            );
        }
    }

    #[test]
    fn raw_nrrd_npy_and_vti_agree() {
        let dims = [3, 4, 5];
        let v = ramp(dims);
        let le: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        let be: Vec<u8> = v.iter().flat_map(|x| x.to_be_bytes()).collect();
        let expect = Values::U16(v.clone());

        let layout = RawLayout {
            dims,
            ty: RawType::U16,
            big_endian: true,
            origin: DVec3::new(1.0, 2.0, 3.0),
            spacing: DVec3::new(0.5, 0.5, 2.0),
        };
        let raw = read_raw(&be, "a.raw", layout).unwrap();
        assert_eq!(raw.values, expect);
        assert_eq!(raw.lattice.spacing, layout.spacing);
        let short = read_raw(&be[1..], "a.raw", layout).unwrap_err();
        assert!(
            short
                .to_string()
                .contains("needs 120 bytes, the file holds 119"),
            "{short}"
        );

        let head = "NRRD0004\ntype: unsigned short\ndimension: 3\nsizes: 3 4 5\nendian: little\nspace directions: (0.5,0,0) (0,0.5,0) (0,0,2)\nspace origin: (1,2,3)\n";
        let mut plain = format!("{head}encoding: raw\n\n").into_bytes();
        plain.extend_from_slice(&le);
        let n = read_nrrd(&plain, "a.nrrd").unwrap();
        assert_eq!(n.values, expect);
        assert_eq!(n.lattice, raw.lattice);
        let mut gz = format!("{head}encoding: gzip\n\n").into_bytes();
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        std::io::Write::write_all(&mut enc, &le).unwrap();
        gz.extend_from_slice(&enc.finish().unwrap());
        assert_eq!(read_nrrd(&gz, "a.nrrd").unwrap().values, expect);
        let cut = read_nrrd(&plain[..plain.len() - 3], "a.nrrd").unwrap_err();
        assert!(cut.to_string().contains("truncated"), "{cut}");
        let cut = read_nrrd(&gz[..gz.len() - 10], "a.nrrd").unwrap_err();
        assert!(cut.to_string().contains("a.nrrd"), "{cut}");
        // The member's CRC-32 (the trailer's first four bytes) is checked: a stream whose
        // data and CRC disagree is refused, not read as values.
        let mut flipped = gz.clone();
        let crc_at = flipped.len() - 8;
        flipped[crc_at] ^= 0x01;
        let bad = read_nrrd(&flipped, "a.nrrd").unwrap_err();
        assert!(bad.to_string().contains("gzip data"), "{bad}");

        let npy = super::super::npy::tests::npy("<u2", "(5, 4, 3)", false, &le);
        let (d, ty, endian, data) = super::super::npy::read_npy_volume(&npy, "a.npy").unwrap();
        assert_eq!((d, ty, endian), (dims, Scalar::U16, Endian::Little));
        assert_eq!(decode(ty, data, endian).values(), expect);
        let bad = super::super::npy::tests::npy("<u2", "(60,)", false, &le);
        assert!(super::super::npy::read_npy_volume(&bad, "a.npy").is_err());

        let text: Vec<String> = v.iter().map(|x| x.to_string()).collect();
        let vti = format!(
            r#"<?xml version="1.0"?>
<VTKFile type="ImageData" version="1.0" byte_order="LittleEndian">
<ImageData WholeExtent="2 4 0 3 0 4" Origin="0 2 3" Spacing="0.5 0.5 2">
<Piece Extent="2 4 0 3 0 4"><PointData Scalars="density">
<DataArray type="Float32" Name="other" NumberOfComponents="3" format="ascii">{}</DataArray>
<DataArray type="UInt16" Name="density" format="ascii">{}</DataArray>
</PointData></Piece></ImageData></VTKFile>
"#,
            vec!["0"; 180].join(" "),
            text.join(" ")
        );
        let vol = read_vti(vti.as_bytes(), "a.vti", None).unwrap();
        assert_eq!(vol.values, expect);
        assert_eq!(vol.lattice, raw.lattice);
        let e = read_vti(vti.as_bytes(), "a.vti", Some("nope")).unwrap_err();
        assert!(e.to_string().contains("no point array 'nope'"), "{e}");
        let e = read_vti(vti.as_bytes(), "a.vti", Some("other")).unwrap_err();
        assert!(e.to_string().contains("3 components"), "{e}");
    }

    /// The data starts where "line skip" and "byte skip" put it, not at the file's end
    /// (trailing bytes used to shift every value), and a header field that does not parse
    /// is an error naming it, not its default.
    #[test]
    fn nrrd_skips_are_honoured_and_bad_fields_named() {
        let dims = [3, 4, 5];
        let v = ramp(dims);
        let le: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        let expect = Values::U16(v);
        let head = "NRRD0004\ntype: uint16\ndimension: 3\nsizes: 3 4 5\n";
        let file = |fields: &str, before: &[u8], data: &[u8], after: &[u8]| {
            let mut f = format!("{head}{fields}\n").into_bytes();
            f.extend_from_slice(before);
            f.extend_from_slice(data);
            f.extend_from_slice(after);
            f
        };
        let read = |f: &[u8]| read_nrrd(f, "s.nrrd");
        // Trailing bytes after the data (a newline some writers append) change nothing.
        assert_eq!(read(&file("", b"", &le, b"\n")).unwrap().values, expect);
        assert_eq!(
            read(&file("byte skip: 7\n", b"padding", &le, b"xyz"))
                .unwrap()
                .values,
            expect
        );
        assert_eq!(
            read(&file("line skip: 2\n", b"one\ntwo\n", &le, b""))
                .unwrap()
                .values,
            expect
        );
        assert_eq!(
            read(&file("lineskip: 1\nbyteskip: 2\n", b"l\nbb", &le, b""))
                .unwrap()
                .values,
            expect
        );
        assert_eq!(
            read(&file("byte skip: -1\n", b"whatever", &le, b""))
                .unwrap()
                .values,
            expect
        );
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        std::io::Write::write_all(&mut enc, b"skipme").unwrap();
        std::io::Write::write_all(&mut enc, &le).unwrap();
        let gz = enc.finish().unwrap();
        let skipped = file(
            "encoding: gzip\nline skip: 1\nbyte skip: 6\n",
            b"x\n",
            &gz,
            b"",
        );
        assert_eq!(read(&skipped).unwrap().values, expect);

        for (fields, words) in [
            ("byte skip: 300\n", &["truncated", "byte skip: 300"][..]),
            ("line skip: 3\n", &["line skip: 3", "passes the end"]),
            ("byte skip: -2\n", &["'byte skip'", "-2"]),
            ("encoding: gzip\nbyte skip: -1\n", &["needs raw encoding"]),
            ("spacings: 1 0.5\n", &["'spacings'", "2 values"]),
            ("spacings: 1 x 1\n", &["'spacings'", "'x' is not a number"]),
            ("spacings: 1 nan 1\n", &["'spacings'", "not finite"]),
            ("space origin: (0,0)\n", &["'space origin'", "2 values"]),
            (
                "space directions: (1,0,0) (0,1,0) (0,0,nan)\n",
                &["'space directions'", "not finite"],
            ),
            (
                "space directions: none (1,0,0) (0,1,0)\n",
                &["'space directions'", "axis 0"],
            ),
            ("space directions: (1,0,0) (0,1,0)\n", &["2 vectors"]),
            ("space directions: (1,0,0) (0,0,0) (0,0,1)\n", &["spacing"]),
            ("endian: middle\n", &["'endian'", "middle"]),
        ] {
            let e = read(&file(fields, b"", &le, b"")).unwrap_err().to_string();
            assert!(e.contains("s.nrrd"), "{fields}: {e}");
            for w in words {
                assert!(e.contains(w), "{fields}: '{w}' not in: {e}");
            }
        }
    }

    #[test]
    fn a_vti_spacing_or_origin_that_is_not_finite_is_named() {
        let vti = |origin: &str, spacing: &str| {
            format!(
                r#"<VTKFile type="ImageData" version="1.0" byte_order="LittleEndian">
<ImageData WholeExtent="1 2 0 1 0 1" Origin="{origin}" Spacing="{spacing}">
<Piece Extent="1 2 0 1 0 1"><PointData Scalars="d">
<DataArray type="Float32" Name="d" format="ascii">0 1 2 3 4 5 6 7</DataArray>
</PointData></Piece></ImageData></VTKFile>"#
            )
        };
        assert!(read_vti(vti("0 0 0", "1 1 1").as_bytes(), "v.vti", None).is_ok());
        for (origin, spacing, named) in [
            ("0 0 0", "nan 1 1", "Spacing=\"nan 1 1\" is not finite"),
            ("0 inf 0", "1 1 1", "Origin=\"0 inf 0\" is not finite"),
        ] {
            let e = read_vti(vti(origin, spacing).as_bytes(), "v.vti", None).unwrap_err();
            assert!(e.to_string().contains(named), "{e}");
        }
        // VTK 9's Direction: the identity reads as before; rotated or flipped axes are
        // refused, not read past (the volume would be placed wrongly).
        let directed = |d: &str| {
            vti("0 0 0", "1 1 1").replace("Spacing=", &format!("Direction=\"{d}\" Spacing="))
        };
        assert!(read_vti(directed("1 0 0 0 1 0 0 0 1").as_bytes(), "v.vti", None).is_ok());
        let e = read_vti(directed("-1 0 0 0 1 0 0 0 1").as_bytes(), "v.vti", None).unwrap_err();
        assert!(
            e.to_string().contains("v.vti") && e.to_string().contains("Direction [-1.0, 0.0"),
            "{e}"
        );
    }

    /// A header claiming 10^15 nodes over three values is refused by what the file
    /// holds, before anything is sized by the claim (it used to abort the process on an
    /// 8 PB allocation).
    #[test]
    fn a_vti_extent_beyond_its_data_is_refused_before_allocating() {
        let vti = r#"<?xml version="1.0"?>
<VTKFile type="ImageData" version="0.1" byte_order="LittleEndian">
<ImageData WholeExtent="0 99999 0 99999 0 99999" Origin="0 0 0" Spacing="1 1 1">
<Piece Extent="0 99999 0 99999 0 99999"><PointData Scalars="s">
<DataArray type="Float32" Name="s" format="ascii">0 1 2</DataArray>
</PointData></Piece></ImageData></VTKFile>"#;
        let e = read_vti(vti.as_bytes(), "huge.vti", None).unwrap_err();
        assert!(
            e.to_string().contains("huge.vti") && e.to_string().contains("holds 3"),
            "{e}"
        );
    }
}
