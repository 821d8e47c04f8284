//! Parsing a VTK XML file into pieces and arrays, and decoding an array's values from
//! wherever and however the file stores them.

use super::super::numeric::{byte_len, parse_number, show, Endian, Scalar, Tokens};
use crate::error::{Error, Result};
use base64::Engine;
use quick_xml::events::{BytesStart, Event};
use std::borrow::Cow;
use std::io::Read;

/// Where an array's values are.
#[derive(Debug)]
enum Format {
    Ascii,
    Binary,
    Appended(usize),
}

#[derive(Debug)]
pub(super) struct DataArray {
    /// The element the array sits in: Points, PointData, Polys, Cells ...
    pub(super) section: String,
    pub(super) name: String,
    /// `None` for types that are not numbers (String, Bit).
    pub(super) ty: Option<Scalar>,
    pub(super) type_name: String,
    pub(super) components: usize,
    format: Format,
    /// Inline content (ascii numbers or base64).
    text: Vec<u8>,
}

#[derive(Debug, Default)]
pub(super) struct Piece {
    pub(super) points: usize,
    /// `Extent` of an ImageData piece (x0 x1 y0 y1 z0 z1), nodes inclusive.
    pub(super) extent: Option<[i64; 6]>,
    polys: usize,
    /// NumberOfCells of an UnstructuredGrid piece.
    pub(super) cells: usize,
    pub(super) normals_name: Option<String>,
    /// The point data's active scalars (`Scalars=` attribute).
    pub(super) scalars_name: Option<String>,
    pub(super) arrays: Vec<DataArray>,
}

/// `WholeExtent`, `Origin` and `Spacing` of an `<ImageData>` element.
#[derive(Debug, Clone, Copy)]
pub(super) struct ImageGeometry {
    pub(super) whole_extent: [i64; 6],
    pub(super) origin: [f64; 3],
    pub(super) spacing: [f64; 3],
}

/// Appended data: the bytes after the `_` marker.
enum Appended<'a> {
    Raw(&'a [u8]),
    Base64(&'a [u8]),
}

pub(super) struct Document<'a> {
    name: &'a str,
    pub(super) kind: String,
    /// The `version` attribute of <VTKFile>, if any ("2.2" ...).
    pub(super) version: Option<String>,
    endian: Endian,
    header: Scalar,
    compressed: bool,
    pub(super) pieces: Vec<Piece>,
    /// Geometry of an ImageData file.
    pub(super) image: Option<ImageGeometry>,
    appended: Option<Appended<'a>>,
    /// Sorted offsets of all appended arrays: a base64 array runs to the next one.
    appended_offsets: Vec<usize>,
}

impl<'a> Document<'a> {
    fn err(&self, message: impl Into<String>) -> Error {
        Error::format(self.name, message)
    }

    pub(super) fn parse(bytes: &'a [u8], name: &'a str) -> Result<Self> {
        let err = |m: String| Error::format(name, m);
        let (xml, appended_start) = match find(bytes, b"<AppendedData") {
            Some(tag) => {
                let close = find(&bytes[tag..], b">")
                    .map(|i| tag + i + 1)
                    .ok_or_else(|| err("truncated: the AppendedData tag is not closed".into()))?;
                let underscore = bytes[close..]
                    .iter()
                    .position(|&b| b == b'_')
                    .map(|i| close + i + 1)
                    .ok_or_else(|| err("truncated: no '_' starting the appended data".into()))?;
                (&bytes[..close], Some(underscore))
            }
            None => (bytes, None),
        };

        let mut doc = Document {
            name,
            kind: String::new(),
            version: None,
            endian: Endian::Little,
            header: Scalar::U32,
            compressed: false,
            pieces: Vec::new(),
            image: None,
            appended: None,
            appended_offsets: Vec::new(),
        };
        let mut appended_encoding = String::from("raw");
        let mut reader = quick_xml::Reader::from_reader(xml);
        reader.config_mut().trim_text(true);
        reader.config_mut().check_end_names = false;
        let mut stack: Vec<String> = Vec::new();
        // Index of the DataArray whose text is being collected, as (piece, array).
        let mut open_array: Option<(usize, usize)> = None;
        loop {
            let event = reader.read_event().map_err(|e| {
                err(format!(
                    "malformed XML at byte {}: {e}",
                    reader.error_position()
                ))
            })?;
            match event {
                Event::Start(e) => {
                    let tag = local_name(&e);
                    let opened = doc.element(
                        &e,
                        &tag,
                        stack.last().map(String::as_str),
                        &mut appended_encoding,
                    )?;
                    if tag == "DataArray" {
                        open_array = opened;
                    }
                    stack.push(tag);
                }
                Event::Empty(e) => {
                    let tag = local_name(&e);
                    doc.element(
                        &e,
                        &tag,
                        stack.last().map(String::as_str),
                        &mut appended_encoding,
                    )?;
                }
                Event::End(_) => {
                    let closed = stack.pop();
                    if closed.as_deref() == Some("DataArray") {
                        open_array = None;
                    }
                }
                Event::Text(t) => {
                    if let (Some((p, a)), Some("DataArray")) =
                        (open_array, stack.last().map(String::as_str))
                    {
                        let text = &mut doc.pieces[p].arrays[a].text;
                        text.extend_from_slice(&t);
                        text.push(b' ');
                    }
                }
                Event::CData(t) => {
                    if let Some((p, a)) = open_array {
                        doc.pieces[p].arrays[a].text.extend_from_slice(&t);
                    }
                }
                Event::Eof => break,
                _ => {}
            }
        }
        if doc.kind.is_empty() {
            return Err(err(
                "not a VTK XML file (no <VTKFile type=...> element)".into()
            ));
        }
        // Every VTK XML file ends with its closing tag; without it the file was cut short,
        // perhaps in arrays this reader would not otherwise look at.
        let end = bytes
            .iter()
            .rposition(|b| !b.is_ascii_whitespace() && *b != 0)
            .map_or(0, |i| i + 1);
        if !bytes[..end].ends_with(b"</VTKFile>") {
            return Err(err(
                "truncated: the file does not end with </VTKFile>".into()
            ));
        }
        if doc.pieces.is_empty() {
            return Err(err(format!(
                "truncated or empty: the {} has no Piece",
                doc.kind
            )));
        }
        if let Some(start) = appended_start {
            let data = &bytes[start.min(bytes.len())..];
            doc.appended = Some(match appended_encoding.as_str() {
                "raw" => Appended::Raw(data),
                "base64" => {
                    let end = data.iter().position(|&b| b == b'<').unwrap_or(data.len());
                    Appended::Base64(&data[..end])
                }
                other => {
                    return Err(err(format!(
                        "AppendedData encoding '{}' is not raw or base64",
                        show(other.as_bytes())
                    )))
                }
            });
        }
        doc.appended_offsets = doc
            .pieces
            .iter()
            .flat_map(|p| &p.arrays)
            .filter_map(|a| match a.format {
                Format::Appended(o) => Some(o),
                _ => None,
            })
            .collect();
        doc.appended_offsets.sort_unstable();
        doc.appended_offsets.dedup();
        Ok(doc)
    }

    /// Handles one start (or empty) element; returns the (piece, array) index of a DataArray.
    fn element(
        &mut self,
        e: &BytesStart,
        tag: &str,
        parent: Option<&str>,
        appended_encoding: &mut String,
    ) -> Result<Option<(usize, usize)>> {
        let file = self.name;
        let attr = |key: &str| -> Result<Option<String>> {
            match e.try_get_attribute(key) {
                Ok(Some(a)) => Ok(Some(
                    a.unescape_value()
                        .map_err(|x| {
                            Error::format(file, format!("bad attribute {key} on <{tag}>: {x}"))
                        })?
                        .trim()
                        .to_string(),
                )),
                Ok(None) => Ok(None),
                Err(x) => Err(Error::format(
                    file,
                    format!("bad attributes on <{tag}>: {x}"),
                )),
            }
        };
        match tag {
            "VTKFile" => {
                self.kind = attr("type")?.unwrap_or_default();
                self.version = attr("version")?;
                if self.kind.is_empty() {
                    return Err(self.err("<VTKFile> has no type attribute"));
                }
                self.endian = match attr("byte_order")?.as_deref() {
                    None | Some("LittleEndian") => Endian::Little,
                    Some("BigEndian") => Endian::Big,
                    Some(other) => {
                        return Err(
                            self.err(format!("unknown byte_order '{}'", show(other.as_bytes())))
                        )
                    }
                };
                self.header = match attr("header_type")?.as_deref() {
                    None | Some("UInt32") => Scalar::U32,
                    Some("UInt64") => Scalar::U64,
                    Some(other) => {
                        return Err(self.err(format!(
                            "unknown header_type '{}' (expected UInt32 or UInt64)",
                            show(other.as_bytes())
                        )))
                    }
                };
                self.compressed = match attr("compressor")?.as_deref() {
                    None | Some("") => false,
                    Some("vtkZLibDataCompressor") => true,
                    Some(other) => {
                        return Err(self.err(format!(
                            "compressor '{}' is not supported (only vtkZLibDataCompressor); re-save the file with zlib or no compression",
                            show(other.as_bytes())
                        )))
                    }
                };
            }
            "Piece" => {
                let count = |key: &str| -> Result<usize> {
                    match attr(key)? {
                        None => Ok(0),
                        Some(v) => v.parse().map_err(|_| {
                            self.err(format!(
                                "Piece {key}=\"{}\" is not a count",
                                show(v.as_bytes())
                            ))
                        }),
                    }
                };
                let extent = match attr("Extent")? {
                    Some(text) => Some(self.numbers::<6, i64>(&text, "Piece Extent")?),
                    None => None,
                };
                let piece = Piece {
                    points: count("NumberOfPoints")?,
                    polys: count("NumberOfPolys")?,
                    cells: count("NumberOfCells")?,
                    extent,
                    ..Piece::default()
                };
                self.pieces.push(piece);
            }
            "ImageData" => {
                let get = |key: &str| -> Result<String> {
                    attr(key)?
                        .ok_or_else(|| self.err(format!("<ImageData> has no {key} attribute")))
                };
                let whole_extent = self.numbers::<6, i64>(&get("WholeExtent")?, "WholeExtent")?;
                let origin = match attr("Origin")? {
                    Some(t) => self.finite(&t, "Origin")?,
                    None => [0.0; 3],
                };
                let spacing = match attr("Spacing")? {
                    Some(t) => self.finite(&t, "Spacing")?,
                    None => [1.0; 3],
                };
                // VTK 9 writes the image's axes (rotated, or an index running against an
                // axis) as a row-major 3×3 Direction: read past, the volume would be
                // placed and oriented wrongly without a word.
                if let Some(t) = attr("Direction")? {
                    let d = self.numbers::<9, f64>(&t, "Direction")?;
                    if d != [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0] {
                        return Err(self.err(format!(
                            "<ImageData> Direction {d:?} is not the identity: rotated or \
                             flipped image axes are not supported (resample the image, e.g. \
                             with ParaView's Resample To Image, first)"
                        )));
                    }
                }
                self.image = Some(ImageGeometry {
                    whole_extent,
                    origin,
                    spacing,
                });
            }
            "PointData" => {
                let normals = attr("Normals")?;
                let scalars = attr("Scalars")?;
                if let Some(piece) = self.pieces.last_mut() {
                    piece.normals_name = normals;
                    piece.scalars_name = scalars;
                }
            }
            "AppendedData" => {
                *appended_encoding = attr("encoding")?.unwrap_or_else(|| "raw".into());
            }
            "DataArray" => {
                let section = parent.unwrap_or("").to_string();
                let Some(piece_index) = self.pieces.len().checked_sub(1) else {
                    // Field data outside any piece: nothing for us.
                    return Ok(None);
                };
                let type_name = attr("type")?.unwrap_or_default();
                let name = attr("Name")?.unwrap_or_default();
                let components = match attr("NumberOfComponents")? {
                    None => 1,
                    Some(v) => v.parse::<usize>().ok().filter(|&c| c > 0).ok_or_else(|| {
                        self.err(format!(
                            "DataArray '{name}': NumberOfComponents=\"{}\" is not a positive count",
                            show(v.as_bytes())
                        ))
                    })?,
                };
                let format = match attr("format")?.as_deref() {
                    Some("ascii") => Format::Ascii,
                    Some("binary") => Format::Binary,
                    Some("appended") => {
                        let offset =
                            attr("offset")?
                                .and_then(|o| o.parse().ok())
                                .ok_or_else(|| {
                                    self.err(format!(
                                        "DataArray '{name}' is appended but has no valid offset"
                                    ))
                                })?;
                        Format::Appended(offset)
                    }
                    other => {
                        return Err(self.err(format!(
                            "DataArray '{name}': unknown format '{}'",
                            show(other.unwrap_or("").as_bytes())
                        )))
                    }
                };
                let array = DataArray {
                    section,
                    name,
                    ty: xml_type(&type_name),
                    type_name,
                    components,
                    format,
                    text: Vec::new(),
                };
                let piece = &mut self.pieces[piece_index];
                piece.arrays.push(array);
                return Ok(Some((piece_index, piece.arrays.len() - 1)));
            }
            _ => {}
        }
        Ok(None)
    }

    /// Exactly `N` whitespace-separated numbers from an attribute's text.
    /// Three finite numbers: an `Origin` or `Spacing` (a NaN spacing would otherwise
    /// surface as a NaN origin, the extent's start times the spacing).
    fn finite(&self, text: &str, what: &str) -> Result<[f64; 3]> {
        let v = self.numbers::<3, f64>(text, what)?;
        if v.iter().all(|x| x.is_finite()) {
            Ok(v)
        } else {
            Err(self.err(format!(
                "{what}=\"{}\" is not finite",
                show(text.as_bytes())
            )))
        }
    }

    fn numbers<const N: usize, T: std::str::FromStr + Copy + Default>(
        &self,
        text: &str,
        what: &str,
    ) -> Result<[T; N]> {
        let parsed: Vec<T> = text
            .split_whitespace()
            .map(str::parse)
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| {
                self.err(format!(
                    "{what}=\"{}\" is not {N} numbers",
                    show(text.as_bytes())
                ))
            })?;
        <[T; N]>::try_from(parsed).map_err(|_| {
            self.err(format!(
                "{what}=\"{}\" is not {N} numbers",
                show(text.as_bytes())
            ))
        })
    }

    /// The piece's point coordinates, item-major.
    pub(super) fn points(&self, piece: &Piece) -> Result<Vec<f64>> {
        let Some(a) = piece.arrays.iter().find(|a| a.section == "Points") else {
            return Err(self.err(format!("the {} piece has no Points array", self.kind)));
        };
        if a.components != 3 {
            return Err(self.err(format!(
                "Points has {} components, expected 3",
                a.components
            )));
        }
        if a.ty.is_none() {
            return Err(self.err(format!("Points has non-numeric type '{}'", a.type_name)));
        }
        self.values(a, piece.points)
    }

    /// The piece's polygons as triangle fans, with indices shifted by `base`.
    pub(super) fn polygons(&self, piece: &Piece, base: usize) -> Result<Vec<[u32; 3]>> {
        let find = |n: &str| {
            piece
                .arrays
                .iter()
                .find(|a| a.section == "Polys" && a.name == n && a.ty.is_some())
        };
        let (Some(conn), Some(offs)) = (find("connectivity"), find("offsets")) else {
            if piece.polys == 0 {
                return Ok(Vec::new());
            }
            return Err(self.err("Polys lacks its connectivity or offsets array"));
        };
        let offsets = self.values(offs, piece.polys)?;
        let total = offsets.last().copied().unwrap_or(0.0);
        let count = if total >= 0.0 && total.fract() == 0.0 && total < usize::MAX as f64 {
            total as usize
        } else {
            return Err(self.err(format!("Polys offsets end in the invalid value {total}")));
        };
        let connectivity = self.values_n(conn, count)?;
        let mut tris = Vec::with_capacity(count.saturating_sub(2 * piece.polys));
        let mut start = 0usize;
        for (k, &end) in offsets.iter().enumerate() {
            let end = end as usize;
            if end < start || end > connectivity.len() {
                return Err(self.err(format!("Polys offset {k} ({end}) is out of order or range")));
            }
            let poly = &connectivity[start..end];
            let index = |v: f64| -> Result<u32> {
                let i = (v >= 0.0 && (v as usize) < piece.points)
                    .then(|| v as usize + base)
                    .and_then(|i| u32::try_from(i).ok());
                i.ok_or_else(|| {
                    self.err(format!(
                        "polygon {k} refers to point {v}, but the piece has {}",
                        piece.points
                    ))
                })
            };
            for j in 1..poly.len().saturating_sub(1) {
                tris.push([index(poly[0])?, index(poly[j])?, index(poly[j + 1])?]);
            }
            start = end;
        }
        Ok(tris)
    }

    /// `tuples * components` values of an array.
    pub(super) fn values(&self, a: &DataArray, tuples: usize) -> Result<Vec<f64>> {
        let count = tuples.checked_mul(a.components).ok_or_else(|| {
            self.err(format!(
                "DataArray '{}' declares an impossible size",
                a.name
            ))
        })?;
        self.values_n(a, count)
    }

    /// Exactly `count` values of an array, from wherever the array stores them.
    fn values_n(&self, a: &DataArray, count: usize) -> Result<Vec<f64>> {
        let Some(ty) = a.ty else {
            return Err(self.err(format!(
                "DataArray '{}' has non-numeric type '{}'",
                a.name, a.type_name
            )));
        };
        let expected_bytes = byte_len(count as u64, ty.size() as u64).ok_or_else(|| {
            self.err(format!(
                "DataArray '{}' declares an impossible size",
                a.name
            ))
        })?;
        let blob: Cow<[u8]> =
            match a.format {
                Format::Ascii => return self.ascii_values(a, ty, count),
                Format::Binary => Cow::Owned(decode_base64(&a.text).map_err(|e| {
                    self.err(format!("DataArray '{}': bad base64 data: {e}", a.name))
                })?),
                Format::Appended(offset) => match &self.appended {
                    None => {
                        return Err(self.err(format!(
                        "DataArray '{}' is appended but the file has no AppendedData (truncated?)",
                        a.name
                    )))
                    }
                    Some(Appended::Raw(data)) => Cow::Borrowed(
                        data.get(offset..)
                            .ok_or_else(|| self.truncated(a, 0, expected_bytes))?,
                    ),
                    Some(Appended::Base64(text)) => {
                        let end = self
                            .appended_offsets
                            .iter()
                            .find(|&&o| o > offset)
                            .copied()
                            .unwrap_or(text.len())
                            .min(text.len());
                        let slice = text
                            .get(offset..end)
                            .ok_or_else(|| self.truncated(a, 0, expected_bytes))?;
                        Cow::Owned(decode_base64(slice).map_err(|e| {
                            self.err(format!("DataArray '{}': bad base64 data: {e}", a.name))
                        })?)
                    }
                },
            };
        let payload = self.unpack(a, &blob, expected_bytes)?;
        Ok(ty.decode(&payload, self.endian))
    }

    fn truncated(&self, a: &DataArray, have: usize, want: usize) -> Error {
        self.err(format!(
            "truncated: DataArray '{}' needs {want} bytes but the file holds {have}",
            a.name
        ))
    }

    fn ascii_values(&self, a: &DataArray, ty: Scalar, count: usize) -> Result<Vec<f64>> {
        let mut tokens = Tokens::new(&a.text);
        // Two bytes per value at least: bounds the reservation for absurd declared counts.
        let mut out = Vec::with_capacity(count.min(a.text.len() / 2 + 1));
        while let Some(t) = tokens.next_token() {
            if out.len() == count {
                return Err(self.err(format!(
                    "DataArray '{}' holds more than the {count} values declared",
                    a.name
                )));
            }
            out.push(ty.narrow(parse_number(t).ok_or_else(|| {
                self.err(format!(
                    "DataArray '{}': '{}' is not a number",
                    a.name,
                    show(t)
                ))
            })?));
        }
        if out.len() != count {
            return Err(self.err(format!(
                "truncated: DataArray '{}' declares {count} values but holds {}",
                a.name,
                out.len()
            )));
        }
        Ok(out)
    }

    /// Strips the size header and, for compressed files, inflates the blocks.
    fn unpack<'b>(&self, a: &DataArray, blob: &'b [u8], expected: usize) -> Result<Cow<'b, [u8]>> {
        let hs = self.header.size();
        let header = |i: usize| -> Result<usize> {
            let bytes = blob
                .get(i * hs..(i + 1) * hs)
                .ok_or_else(|| self.truncated(a, blob.len(), (i + 1) * hs))?;
            usize::try_from(self.header.read_one(bytes, self.endian) as u64)
                .map_err(|_| self.err(format!("DataArray '{}': size header too large", a.name)))
        };
        if !self.compressed {
            let n = header(0)?;
            if n != expected {
                return Err(self.err(format!(
                    "DataArray '{}' holds {n} bytes, but its declared size needs {expected}",
                    a.name
                )));
            }
            let data = blob.get(hs..).unwrap_or(&[]);
            if data.len() < n {
                return Err(self.truncated(a, data.len(), n));
            }
            return Ok(Cow::Borrowed(&data[..n]));
        }
        // Compressed: [blocks, block size, last block size, compressed size of each block].
        let blocks = header(0)?;
        let header_len = blocks
            .checked_add(3)
            .and_then(|k| k.checked_mul(hs))
            .filter(|&l| l <= blob.len())
            .ok_or_else(|| self.truncated(a, blob.len(), blocks.saturating_mul(hs)))?;
        let block_size = header(1)?;
        let last_size = header(2)?;
        let total = if blocks == 0 {
            0
        } else {
            let last = if last_size == 0 {
                block_size
            } else {
                last_size
            };
            (blocks - 1)
                .checked_mul(block_size)
                .and_then(|t| t.checked_add(last))
                .unwrap_or(usize::MAX)
        };
        if total != expected {
            return Err(self.err(format!(
                "DataArray '{}' holds {total} bytes, but its declared size needs {expected}",
                a.name
            )));
        }
        let mut sizes = Vec::with_capacity(blocks);
        let mut compressed_total = 0usize;
        for i in 0..blocks {
            let s = header(3 + i)?;
            compressed_total = compressed_total.saturating_add(s);
            sizes.push(s);
        }
        let data = &blob[header_len..];
        if data.len() < compressed_total {
            return Err(self.truncated(a, data.len(), compressed_total));
        }
        if total > super::super::inflate_bound(compressed_total) {
            return Err(self.err(format!(
                "DataArray '{}' claims {total} bytes from {compressed_total} compressed (corrupt)",
                a.name
            )));
        }
        // Reserve for a plausible ratio only: a lying header must not cost memory up front.
        let mut out = Vec::with_capacity(total.min(compressed_total.saturating_mul(16)));
        let mut at = 0;
        for (i, &s) in sizes.iter().enumerate() {
            let want = if i + 1 == blocks && last_size != 0 {
                last_size
            } else {
                block_size
            };
            let before = out.len();
            flate2::read::ZlibDecoder::new(&data[at..at + s])
                .take(want as u64)
                .read_to_end(&mut out)
                .map_err(|e| {
                    self.err(format!(
                        "DataArray '{}': corrupt zlib block {i}: {e}",
                        a.name
                    ))
                })?;
            if out.len() - before != want {
                return Err(self.err(format!(
                    "DataArray '{}': zlib block {i} gives {} bytes instead of {want}",
                    a.name,
                    out.len() - before
                )));
            }
            at += s;
        }
        Ok(Cow::Owned(out))
    }
}

fn local_name(e: &BytesStart) -> String {
    String::from_utf8_lossy(e.local_name().as_ref()).into_owned()
}

fn xml_type(name: &str) -> Option<Scalar> {
    Some(match name {
        "Int8" | "Char" => Scalar::I8,
        "UInt8" | "UChar" => Scalar::U8,
        "Int16" => Scalar::I16,
        "UInt16" => Scalar::U16,
        "Int32" => Scalar::I32,
        "UInt32" => Scalar::U32,
        "Int64" | "IdType" => Scalar::I64,
        "UInt64" => Scalar::U64,
        "Float32" => Scalar::F32,
        "Float64" => Scalar::F64,
        _ => return None,
    })
}

pub(crate) fn find(haystack: &[u8], needle: &[u8]) -> Option<usize> {
    haystack.windows(needle.len()).position(|w| w == needle)
}

/// Decodes base64 that may be several padded streams back to back: VTK encodes the size
/// header of compressed arrays separately from the data, so '=' can occur mid-text.
fn decode_base64(text: &[u8]) -> std::result::Result<Vec<u8>, base64::DecodeError> {
    const LENIENT: base64::engine::GeneralPurpose = base64::engine::GeneralPurpose::new(
        &base64::alphabet::STANDARD,
        base64::engine::GeneralPurposeConfig::new()
            .with_decode_padding_mode(base64::engine::DecodePaddingMode::Indifferent)
            .with_decode_allow_trailing_bits(true),
    );
    let clean: Vec<u8> = text
        .iter()
        .copied()
        .filter(|b| !b.is_ascii_whitespace())
        .collect();
    let mut out = Vec::with_capacity(clean.len() / 4 * 3 + 3);
    let mut start = 0;
    let mut i = 0;
    while i < clean.len() {
        if clean[i] == b'=' {
            while i < clean.len() && clean[i] == b'=' {
                i += 1;
            }
            LENIENT.decode_vec(&clean[start..i], &mut out)?;
            start = i;
        } else {
            i += 1;
        }
    }
    if start < clean.len() {
        LENIENT.decode_vec(&clean[start..], &mut out)?;
    }
    Ok(out)
}
