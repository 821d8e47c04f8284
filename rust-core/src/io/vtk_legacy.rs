//! Legacy VTK (`.vtk`) point sets, ASCII or BINARY (big-endian), versions 2 to 5.1.
//!
//! Only the point list and the POINT_DATA arrays matter for particles; cells, cell data,
//! lookup tables and metadata are parsed only to be skipped, because in a BINARY file the
//! only way past a block is to know its size.

use super::numeric::{byte_len, parse_number, show, Endian, Scalar, Tokens};
use crate::error::{Error, Result};
use crate::field::particles::{Attribute, ParticleData, Skipped};

/// Reads the points and point arrays of a legacy VTK file.
pub(crate) fn read(bytes: &[u8], name: &str) -> Result<ParticleData> {
    let mut r = Reader {
        bytes,
        pos: 0,
        binary: false,
        name,
    };
    let magic = r.raw_line();
    if !magic.to_ascii_lowercase().starts_with("# vtk datafile") {
        return Err(r.err(format!(
            "not a legacy VTK file: the first line is '{}' instead of '# vtk DataFile Version ...'",
            show(magic.as_bytes())
        )));
    }
    let _title = r.raw_line();
    let mode = r.line().unwrap_or_default();
    r.binary = match mode.to_ascii_uppercase().as_str() {
        "ASCII" => false,
        "BINARY" => true,
        other => {
            return Err(r.err(format!(
                "the third line must say ASCII or BINARY, not '{}'",
                show(other.as_bytes())
            )))
        }
    };
    let dataset = r.line().unwrap_or_default();
    let mut words = dataset.split_whitespace();
    if !words
        .next()
        .is_some_and(|w| w.eq_ignore_ascii_case("DATASET"))
    {
        return Err(r.err(format!(
            "expected 'DATASET <type>' after the header, found '{}'",
            show(dataset.as_bytes())
        )));
    }
    let kind = words.next().unwrap_or("").to_ascii_uppercase();
    if !matches!(
        kind.as_str(),
        "UNSTRUCTURED_GRID" | "POLYDATA" | "STRUCTURED_GRID"
    ) {
        return Err(r.err(format!(
            "DATASET {kind} is not a point set; supported: UNSTRUCTURED_GRID, POLYDATA, STRUCTURED_GRID"
        )));
    }
    r.body(kind == "UNSTRUCTURED_GRID")
}

/// Which block the arrays that follow belong to.
#[derive(Clone, Copy, PartialEq)]
enum Section {
    None,
    Point(u64),
    Cell(u64),
}

struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
    binary: bool,
    name: &'a str,
}

impl<'a> Reader<'a> {
    fn err(&self, message: impl Into<String>) -> Error {
        Error::format(self.name, message)
    }

    /// The rest of the current line, without its line break (the title may be blank).
    fn raw_line(&mut self) -> String {
        let rest = &self.bytes[self.pos.min(self.bytes.len())..];
        let end = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
        self.pos += (end + 1).min(rest.len());
        String::from_utf8_lossy(&rest[..end]).trim().to_string()
    }

    /// The next non-blank line, trimmed; `None` at the end of the file.
    fn line(&mut self) -> Option<String> {
        while self.pos < self.bytes.len() && self.bytes[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        if self.pos >= self.bytes.len() {
            return None;
        }
        Some(self.raw_line())
    }

    /// The next non-blank line without consuming it.
    fn peek_line(&mut self) -> Option<String> {
        let saved = self.pos;
        let line = self.line();
        self.pos = saved;
        line
    }

    /// Reads `items * comps` values of type `ty` following a `keyword` line. `unit` names the
    /// items in messages ("points", "values of 'velocity'").
    fn values(
        &mut self,
        items: u64,
        comps: u64,
        ty: Scalar,
        keyword: &str,
        unit: &str,
    ) -> Result<Vec<f64>> {
        self.consume(items, comps, ty, keyword, unit, true)
    }

    /// Like [`Self::values`] but only steps over the data.
    fn skip(
        &mut self,
        items: u64,
        comps: u64,
        ty: Scalar,
        keyword: &str,
        unit: &str,
    ) -> Result<()> {
        self.consume(items, comps, ty, keyword, unit, false)
            .map(|_| ())
    }

    fn consume(
        &mut self,
        items: u64,
        comps: u64,
        ty: Scalar,
        keyword: &str,
        unit: &str,
        keep: bool,
    ) -> Result<Vec<f64>> {
        let remaining = self.bytes.len().saturating_sub(self.pos);
        let truncated = |have: u64| {
            self.err(format!(
                "truncated: {keyword} declares {items} {unit} but the file ends after {have}"
            ))
        };
        let count = items.checked_mul(comps).ok_or_else(|| truncated(0))?;
        if self.binary {
            // Binary data starts right after the keyword line's '\n'.
            let item_bytes = comps.saturating_mul(ty.size() as u64).max(1);
            let need = byte_len(count, ty.size() as u64)
                .filter(|&n| n <= remaining)
                .ok_or_else(|| truncated(remaining as u64 / item_bytes))?;
            let data = &self.bytes[self.pos..self.pos + need];
            self.pos += need;
            return Ok(if keep {
                ty.decode(data, Endian::Big)
            } else {
                Vec::new()
            });
        }
        // Each ASCII value takes at least two bytes (digit and separator), which bounds what
        // may be reserved however large the declared count.
        let capacity = if keep {
            count.min(remaining as u64 / 2 + 1)
        } else {
            0
        };
        let mut out = Vec::with_capacity(capacity as usize);
        let mut tokens = Tokens {
            bytes: self.bytes,
            pos: self.pos,
        };
        for k in 0..count {
            let Some(token) = tokens.next_token() else {
                return Err(truncated(k / comps.max(1)));
            };
            let value = parse_number(token);
            match value {
                Some(v) if keep => out.push(ty.narrow(v)),
                Some(_) => {}
                None if token.first().is_some_and(|b| b.is_ascii_alphabetic()) => {
                    // A keyword where a number should be: the block is shorter than declared.
                    return Err(self.err(format!(
                        "{keyword} declares {items} {unit} but only {} are given before '{}'",
                        k / comps.max(1),
                        show(token)
                    )));
                }
                None => {
                    return Err(self.err(format!(
                        "{keyword}: '{}' is not a number (value {} of {count})",
                        show(token),
                        k + 1
                    )))
                }
            }
        }
        self.pos = tokens.pos;
        Ok(out)
    }

    /// Parses everything after the DATASET line.
    fn body(&mut self, unstructured: bool) -> Result<ParticleData> {
        let mut positions: Option<Vec<f64>> = None;
        // An unstructured grid's CELLS come with CELL_TYPES; a file that stops between them
        // was cut short, even though everything before the cut parses.
        let mut cells_without_types = false;
        let mut attributes: Vec<Attribute> = Vec::new();
        let mut skipped = Vec::new();
        let mut section = Section::None;
        while let Some(line) = self.line() {
            let words: Vec<&str> = line.split_whitespace().collect();
            let keyword = words[0].to_ascii_uppercase();
            match keyword.as_str() {
                "POINTS" => {
                    if positions.is_some() {
                        return Err(self.err("a second POINTS block"));
                    }
                    let n = self.count(&words, 1, "POINTS <n> <type>")?;
                    let ty = self.scalar_type(words.get(2).copied(), "POINTS")?;
                    positions = Some(self.values(n, 3, ty, "POINTS", "points")?);
                }
                "CELLS" | "VERTICES" | "LINES" | "POLYGONS" | "TRIANGLE_STRIPS" => {
                    self.skip_cells(&words, &keyword)?;
                    cells_without_types = unstructured && keyword == "CELLS";
                }
                "CELL_TYPES" => {
                    cells_without_types = false;
                    let n = self.count(&words, 1, "CELL_TYPES <n>")?;
                    self.skip(n, 1, Scalar::I32, "CELL_TYPES", "cell types")?;
                }
                "DIMENSIONS" | "ORIGIN" | "SPACING" | "ASPECT_RATIO" => {}
                "POINT_DATA" => {
                    let n = self.count(&words, 1, "POINT_DATA <n>")?;
                    section = Section::Point(n);
                }
                "CELL_DATA" => {
                    let n = self.count(&words, 1, "CELL_DATA <n>")?;
                    section = Section::Cell(n);
                }
                "METADATA" => self.skip_metadata(),
                "FIELD" => self.field(&words, section, &mut attributes)?,
                "LOOKUP_TABLE" => {
                    // A table definition: <size> RGBA entries, bytes in BINARY, floats in ASCII.
                    let n = self.count(&words, 2, "LOOKUP_TABLE <name> <size>")?;
                    let ty = if self.binary { Scalar::U8 } else { Scalar::F32 };
                    self.skip(n, 4, ty, "LOOKUP_TABLE", "colours")?;
                }
                _ => {
                    let items = match section {
                        Section::Point(n) | Section::Cell(n) => n,
                        Section::None => {
                            return Err(self.err(format!(
                                "unexpected '{}' (at byte {})",
                                show(line.as_bytes()),
                                self.pos
                            )))
                        }
                    };
                    match self.attribute(&words, &keyword, items, section)? {
                        Some(a) => attributes.push(a),
                        None => skipped.push(Skipped {
                            name: words[1].to_string(),
                            why: "it is CELL_DATA, one value per cell".into(),
                        }),
                    }
                }
            }
        }
        let Some(flat) = positions else {
            return Err(self.err("no POINTS block"));
        };
        if cells_without_types {
            return Err(self.err("truncated: the file ends after CELLS, before CELL_TYPES"));
        }
        let n = (flat.len() / 3) as u64;
        if let Section::Point(m) = section {
            if m != n {
                return Err(self.err(format!("POINT_DATA declares {m} values for {n} points")));
            }
        }
        Ok(ParticleData {
            positions: super::positions_from_flat(&flat),
            attributes,
            skipped,
        })
    }

    /// One attribute block (SCALARS, VECTORS ...); `None` when it belongs to cells.
    fn attribute(
        &mut self,
        words: &[&str],
        keyword: &str,
        items: u64,
        section: Section,
    ) -> Result<Option<Attribute>> {
        let name = words.get(1).copied().unwrap_or("").to_string();
        let usage = |s: &str| format!("{keyword} {s}");
        let (comps, ty) = match keyword {
            "SCALARS" => {
                let ty = self.scalar_type(words.get(2).copied(), keyword)?;
                let comps = match words.get(3) {
                    Some(_) => self.count(words, 3, &usage("<name> <type> [numComp]"))?,
                    None => 1,
                };
                if self
                    .peek_line()
                    .is_some_and(|l| l.to_ascii_uppercase().starts_with("LOOKUP_TABLE"))
                {
                    self.line();
                }
                (comps, ty)
            }
            "VECTORS" | "NORMALS" => (3, self.scalar_type(words.get(2).copied(), keyword)?),
            "TENSORS" => (9, self.scalar_type(words.get(2).copied(), keyword)?),
            "TENSORS6" => (6, self.scalar_type(words.get(2).copied(), keyword)?),
            "GLOBAL_IDS" | "PEDIGREE_IDS" => (1, self.scalar_type(words.get(2).copied(), keyword)?),
            "TEXTURE_COORDINATES" => {
                let dim = self.count(words, 2, &usage("<name> <dim> <type>"))?;
                (dim, self.scalar_type(words.get(3).copied(), keyword)?)
            }
            "COLOR_SCALARS" => {
                let comps = self.count(words, 2, &usage("<name> <nValues>"))?;
                (comps, if self.binary { Scalar::U8 } else { Scalar::F32 })
            }
            other => {
                return Err(self.err(format!(
                    "unknown keyword '{}' in a data section (at byte {})",
                    show(other.as_bytes()),
                    self.pos
                )))
            }
        };
        if name.is_empty() || comps == 0 {
            return Err(self.err(format!("malformed '{}' line", words.join(" "))));
        }
        let unit = format!("values of '{name}'");
        if !matches!(section, Section::Point(_)) {
            self.skip(items, comps, ty, keyword, &unit)?;
            self.skip_trailing_metadata();
            return Ok(None);
        }
        let data = self.values(items, comps, ty, keyword, &unit)?;
        self.skip_trailing_metadata();
        Ok(Some(Attribute {
            name,
            components: comps as usize,
            data,
        }))
    }

    /// `FIELD <name> <nArrays>` then per array `<name> <numComp> <numTuples> <type>` and data.
    fn field(&mut self, words: &[&str], section: Section, out: &mut Vec<Attribute>) -> Result<()> {
        let arrays = self.count(words, 2, "FIELD <name> <numArrays>")?;
        for _ in 0..arrays {
            let Some(header) = self.line() else {
                return Err(self.err(format!(
                    "truncated: FIELD '{}' declares {arrays} arrays but the file ends",
                    words.get(1).unwrap_or(&"")
                )));
            };
            let w: Vec<&str> = header.split_whitespace().collect();
            let usage = "FIELD array line '<name> <numComp> <numTuples> <type>'";
            let comps = self.count(&w, 1, usage)?;
            let tuples = self.count(&w, 2, usage)?;
            let ty = self.scalar_type(w.get(3).copied(), "FIELD array")?;
            let unit = format!("tuples of '{}'", w[0]);
            let wanted = matches!(section, Section::Point(n) if n == tuples) && comps > 0;
            if wanted {
                let data = self.values(tuples, comps, ty, "FIELD array", &unit)?;
                out.push(Attribute {
                    name: w[0].to_string(),
                    components: comps as usize,
                    data,
                });
            } else if let Section::Point(n) = section {
                return Err(self.err(format!(
                    "FIELD array '{}' has {tuples} tuples but POINT_DATA declares {n}",
                    w[0]
                )));
            } else {
                self.skip(tuples, comps, ty, "FIELD array", &unit)?;
            }
            self.skip_trailing_metadata();
        }
        Ok(())
    }

    /// Connectivity blocks: `KEY <n> <size>` then `size` ints (up to 4.2), or in 5.x
    /// `OFFSETS <type>` with n values and `CONNECTIVITY <type>` with `size` values.
    fn skip_cells(&mut self, words: &[&str], keyword: &str) -> Result<()> {
        let usage = format!("{keyword} <n> <size>");
        let n = self.count(words, 1, &usage)?;
        let size = self.count(words, 2, &usage)?;
        let next = self.peek_line().unwrap_or_default().to_ascii_uppercase();
        if next.starts_with("OFFSETS") {
            for (key, len) in [("OFFSETS", n), ("CONNECTIVITY", size)] {
                let line = self.line().unwrap_or_default();
                let w: Vec<&str> = line.split_whitespace().collect();
                if !w.first().is_some_and(|k| k.eq_ignore_ascii_case(key)) {
                    return Err(self.err(format!(
                        "{keyword}: expected {key}, found '{}'",
                        show(line.as_bytes())
                    )));
                }
                let ty = self.scalar_type(w.get(1).copied(), key)?;
                self.skip(len, 1, ty, key, "values")?;
                self.skip_trailing_metadata();
            }
            Ok(())
        } else {
            self.skip(size, 1, Scalar::I32, keyword, "values")
        }
    }

    /// `METADATA` blocks (5.x) run to the next blank line.
    fn skip_metadata(&mut self) {
        while self.pos < self.bytes.len() {
            let line = self.raw_line();
            if line.is_empty() {
                break;
            }
        }
    }

    fn skip_trailing_metadata(&mut self) {
        if self
            .peek_line()
            .is_some_and(|l| l.eq_ignore_ascii_case("METADATA"))
        {
            self.line();
            self.skip_metadata();
        }
    }

    /// The non-negative integer in `words[index]`.
    fn count(&self, words: &[&str], index: usize, usage: &str) -> Result<u64> {
        words
            .get(index)
            .and_then(|w| w.parse::<u64>().ok())
            .ok_or_else(|| {
                self.err(format!(
                    "malformed line '{}', expected {usage}",
                    show(words.join(" ").as_bytes())
                ))
            })
    }

    fn scalar_type(&self, word: Option<&str>, keyword: &str) -> Result<Scalar> {
        let word = word.unwrap_or("");
        Ok(match word.to_ascii_lowercase().as_str() {
            "float" | "vtktypefloat32" => Scalar::F32,
            "double" | "vtktypefloat64" => Scalar::F64,
            "char" | "signed_char" | "vtktypeint8" => Scalar::I8,
            "unsigned_char" | "vtktypeuint8" => Scalar::U8,
            "short" | "vtktypeint16" => Scalar::I16,
            "unsigned_short" | "vtktypeuint16" => Scalar::U16,
            // VTK writes vtkIdType as 32-bit int in legacy files.
            "int" | "vtkidtype" | "vtktypeint32" => Scalar::I32,
            "unsigned_int" | "vtktypeuint32" => Scalar::U32,
            "long" | "vtktypeint64" => Scalar::I64,
            "unsigned_long" | "vtktypeuint64" => Scalar::U64,
            _ => {
                return Err(self.err(format!(
                    "{keyword}: unsupported data type '{}' (supported: float, double, char, unsigned_char, short, unsigned_short, int, unsigned_int, long, unsigned_long, vtkIdType)",
                    show(word.as_bytes())
                )))
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::super::read_particles_from_bytes;
    use super::super::test_support::*;
    use super::*;

    fn read_str(s: &str) -> Result<ParticleData> {
        read(s.as_bytes(), "t.vtk")
    }

    #[test]
    fn ascii_polydata_with_all_attribute_kinds() {
        let p = read_str(
            "# vtk DataFile Version 3.0\n\nASCII\nDATASET POLYDATA\nPOINTS 2 double\n0 0 0\n1 2 3\n\
             VERTICES 2 4\n1 0\n1 1\nPOINT_DATA 2\nSCALARS rho float\nLOOKUP_TABLE default\n1000 999.5\n\
             SCALARS c int 2\n1 2\n3 4\nVECTORS v float\n1 0 0 0 1 0\nNORMALS n double\n0 0 1 0 0 1\n\
             FIELD fd 1\nmass 1 2 float\n0.5 0.25\nCELL_DATA 2\nSCALARS cd float\nLOOKUP_TABLE default\n7 8\n",
        )
        .unwrap();
        assert_eq!(p.len(), 2);
        assert_eq!(p.positions[1], glam::DVec3::new(1.0, 2.0, 3.0));
        let names: Vec<&str> = p.attributes.iter().map(|a| a.name.as_str()).collect();
        assert_eq!(names, ["rho", "c", "v", "n", "mass"]);
        assert_eq!(p.attribute("c").unwrap().components, 2);
        assert_eq!(p.attribute("c").unwrap().data, vec![1.0, 2.0, 3.0, 4.0]);
        assert_eq!(p.attribute("v").unwrap().components, 3);
        assert_eq!(p.attribute("mass").unwrap().data, vec![0.5, 0.25]);
        let e = p.require("cd").unwrap_err().to_string();
        assert!(
            e.contains("'cd' is not per-particle data: it is CELL_DATA"),
            "{e}"
        );
    }

    #[test]
    fn binary_big_endian_with_version_5_cells() {
        let mut f =
            b"# vtk DataFile Version 5.1\nt\nBINARY\nDATASET UNSTRUCTURED_GRID\nPOINTS 2 float\n"
                .to_vec();
        for v in [0.5f32, 1.0, 1.5, 2.0, 2.5, 3.0] {
            f.extend_from_slice(&v.to_be_bytes());
        }
        f.extend_from_slice(b"\nCELLS 3 2\nOFFSETS vtktypeint64\n");
        for v in [0i64, 1, 2] {
            f.extend_from_slice(&v.to_be_bytes());
        }
        f.extend_from_slice(b"\nCONNECTIVITY vtktypeint64\n");
        for v in [0i64, 1] {
            f.extend_from_slice(&v.to_be_bytes());
        }
        f.extend_from_slice(b"\nCELL_TYPES 2\n\0\0\0\x01\0\0\0\x01\nPOINT_DATA 2\nSCALARS id unsigned_short 1\nLOOKUP_TABLE default\n");
        f.extend_from_slice(&[0, 7, 1, 0]);
        f.extend_from_slice(b"\nMETADATA\nINFORMATION 0\n\n");
        let p = read(&f, "b.vtk").unwrap();
        assert_eq!(p.positions[1].to_array(), [2.0, 2.5, 3.0]);
        assert_eq!(p.attribute("id").unwrap().data, vec![7.0, 256.0]);
    }

    #[test]
    fn errors_name_file_and_problem() {
        let e = read_str(
            "# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\nPOINTS 4 float\n0 0 0 1 1 1\n",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("t.vtk: truncated: POINTS declares 4 points but the file ends after 2"),
            "{e}"
        );
        let e = read_str("# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\nPOINTS 4 float\n0 0 0 1 1 1\nVERTICES 1 2\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("only 2 are given before 'VERTICES'"), "{e}");
        let e = read_str("# vtk DataFile Version 3.0\nx\nASCII\nDATASET STRUCTURED_POINTS\n")
            .unwrap_err();
        assert!(e.to_string().contains("not a point set"), "{e}");
        let e = read_str("hello\n").unwrap_err();
        assert!(e.to_string().contains("not a legacy VTK file"), "{e}");
        let e = read_str(
            "# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\nPOINTS 1 bit\n1 1 1\n",
        )
        .unwrap_err();
        assert!(e.to_string().contains("unsupported data type 'bit'"), "{e}");
        let e = read_str("# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\nPOINTS 1 float\n1 1 1\nPOINT_DATA 2\n")
            .unwrap_err();
        assert!(
            e.to_string()
                .contains("POINT_DATA declares 2 values for 1 points"),
            "{e}"
        );
    }

    #[test]
    fn gigantic_counts_are_refused_before_allocating() {
        let t = std::time::Instant::now();
        for mode in ["BINARY", "ASCII"] {
            let f = format!("# vtk DataFile Version 3.0\nx\n{mode}\nDATASET POLYDATA\nPOINTS 1000000000000000 float\n0 0 0\n");
            let e = read_str(&f).unwrap_err().to_string();
            assert!(e.contains("declares 1000000000000000 points"), "{e}");
            let f = format!("# vtk DataFile Version 3.0\nx\n{mode}\nDATASET POLYDATA\nPOINTS 18446744073709551615 double\n");
            assert!(read_str(&f).is_err());
        }
        assert!(t.elapsed().as_secs_f64() < 1.0);
    }

    #[test]
    fn shared_frames_have_velocity_and_ids() {
        let path = shared_data_dir().join("double_dam_break_frame_26_4732_particles.vtk");
        let p = super::super::read_particles(&path).unwrap();
        assert_eq!(p.len(), 4732);
        let v = p.require("velocity").unwrap();
        assert_eq!(v.components, 3);
        assert_eq!(p.require("id").unwrap().components, 1);
        // ids are a permutation-free labelling of the particles
        let mut ids = p.require("id").unwrap().data.clone();
        ids.sort_by(f64::total_cmp);
        ids.dedup();
        assert_eq!(ids.len(), 4732);
    }

    #[test]
    fn truncated_shared_files_fail_cleanly() {
        for (path, n) in shared_data_files() {
            if path.extension().unwrap() != "vtk" {
                continue;
            }
            let bytes = std::fs::read(&path).unwrap();
            let name = path.file_name().unwrap().to_string_lossy();
            assert_truncations_fail(&bytes, "vtk", &name, n);
            assert_no_cut_panics(&bytes, "vtk", &name);
            let half = read_particles_from_bytes(&bytes[..bytes.len() / 2], "vtk", &name);
            let e = half.unwrap_err().to_string();
            assert!(e.contains("truncated"), "{e}");
        }
    }
}
