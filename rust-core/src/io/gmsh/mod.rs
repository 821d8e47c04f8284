//! Gmsh `.msh` version 4.1 files (ASCII and binary) with high-order volume elements into an
//! [`FeMesh`]: `$MeshFormat`, `$Nodes` (entity blocks, sparse tags), `$Elements` (complete
//! Lagrange tetrahedra, hexahedra and prisms of any order gmsh describes, and the 20-node
//! hexahedra and 15-node prisms of `Mesh.SecondOrderIncomplete`, handed to the mesh as VTK's
//! serendipity cells; lower-dimensional elements are skipped) and `$NodeData` (one point array per field name, from its last
//! time step). Other sections (`$Entities`, `$PhysicalNames`, ...) are skipped.
//!
//! Node order: gmsh numbers high-order nodes differently from VTK. The permutation is not
//! transcribed: `order.rs` (generated from gmsh by `scripts/make_gmsh_order.py`) holds each
//! gmsh node's reference lattice point, and each is matched to the VTK node at the same
//! reference point (`Shape::node_coords`, or the serendipity cell's table in
//! `field::fe::classic`).
//!
//! Errors name the file, the section and the line (ASCII) or byte offset (binary), or the
//! element / node tag; a file that ends inside a section is refused as truncated, and
//! counts the remaining bytes cannot hold are refused before anything is allocated.

mod order;
#[cfg(test)]
mod tests;

use crate::error::{Error, Result};
use crate::field::fe::{classic, FeMesh, Kind, Shape};
use crate::field::particles::Attribute;
use glam::DVec3;
use order::{ELEMENT_TYPES, GMSH_VERSION, UNDESCRIBED_TYPES, VOLUME_TYPES};
use rustc_hash::FxHashMap;

/// Reads a `.msh` 4.1 file's volume elements and node data; see the module docs.
pub(crate) fn read_fe_mesh(bytes: &[u8], name: &str) -> Result<FeMesh> {
    let mut r = Reader {
        b: bytes,
        pos: 0,
        line: 1,
        name,
        section: "file",
        binary: false,
    };
    let mut format_seen = false;
    let mut nodes: Option<Nodes> = None;
    let mut elements: Option<Elements> = None;
    let mut data: Vec<NodeData> = Vec::new();
    while let Some(header) = r.section_header()? {
        if !format_seen && header != "$MeshFormat" {
            return Err(r.err(format!(
                "expected $MeshFormat first, found '{header}' (not a Gmsh .msh file?)"
            )));
        }
        match header {
            "$MeshFormat" => {
                r.section = "$MeshFormat";
                r.mesh_format()?;
                format_seen = true;
            }
            "$Nodes" => {
                r.section = "$Nodes";
                nodes = Some(r.nodes()?);
            }
            "$Elements" => {
                r.section = "$Elements";
                elements = Some(r.elements()?);
            }
            "$NodeData" => {
                r.section = "$NodeData";
                data.push(r.node_data()?);
            }
            other => {
                r.skip_section(other)?;
                continue;
            }
        }
        r.expect_end(header)?;
    }
    if !format_seen {
        return Err(Error::format(
            name,
            "the file is empty or not a Gmsh .msh file",
        ));
    }
    let nodes = nodes.ok_or_else(|| Error::format(name, "the file has no $Nodes section"))?;
    let elements =
        elements.ok_or_else(|| Error::format(name, "the file has no $Elements section"))?;
    assemble(name, nodes, elements, data)
}

/// `$Nodes`: tags and coordinates in file order.
struct Nodes {
    tags: Vec<u64>,
    coords: Vec<DVec3>,
}

/// Volume elements in file order: tag, index into `VOLUME_TYPES`, node tags (gmsh order).
struct Elements {
    tags: Vec<u64>,
    types: Vec<usize>,
    offsets: Vec<usize>,
    nodes: Vec<u64>,
    skipped_lower: usize,
}

/// One `$NodeData` section.
struct NodeData {
    name: String,
    step: i64,
    components: usize,
    tags: Vec<u64>,
    values: Vec<f64>,
}

struct Reader<'a> {
    b: &'a [u8],
    pos: usize,
    /// Current line (meaningful in ASCII parts).
    line: usize,
    name: &'a str,
    section: &'static str,
    binary: bool,
}

impl<'a> Reader<'a> {
    fn err(&self, msg: impl std::fmt::Display) -> Error {
        let at = if self.binary {
            format!("byte {}", self.pos)
        } else {
            format!("line {}", self.line)
        };
        Error::format(self.name, format!("{}, {at}: {msg}", self.section))
    }

    fn truncated(&self) -> Error {
        self.err(format!(
            "the file ends inside {} (truncated?)",
            self.section
        ))
    }

    fn skip_ws(&mut self) {
        while let Some(&c) = self.b.get(self.pos) {
            if c == b'\n' {
                self.line += 1;
            } else if !c.is_ascii_whitespace() {
                break;
            }
            self.pos += 1;
        }
    }

    /// The rest of the current line (without line end), advancing past it.
    fn rest_of_line(&mut self) -> Result<&'a str> {
        let start = self.pos;
        let end = self.b[start..]
            .iter()
            .position(|&c| c == b'\n')
            .map_or(self.b.len(), |k| start + k);
        self.pos = (end + 1).min(self.b.len());
        if end < self.b.len() {
            self.line += 1;
        }
        let s = std::str::from_utf8(&self.b[start..end])
            .map_err(|_| self.err("a text line is not valid UTF-8"))?;
        Ok(s.trim_end_matches('\r').trim())
    }

    /// The next `$Section` line, or None at the end of the file.
    fn section_header(&mut self) -> Result<Option<&'a str>> {
        self.section = "file";
        self.skip_ws();
        if self.pos >= self.b.len() {
            return Ok(None);
        }
        let line = self.rest_of_line()?;
        if !line.starts_with('$') {
            return Err(self.err(format!("expected a $Section line, found '{}'", short(line))));
        }
        Ok(Some(line))
    }

    fn expect_end(&mut self, header: &str) -> Result<()> {
        self.skip_ws();
        if self.pos >= self.b.len() {
            return Err(self.truncated());
        }
        let line = self.rest_of_line()?;
        let want = format!("$End{}", &header[1..]);
        if line != want {
            return Err(self.err(format!(
                "expected {want}, found '{}' (more data than the section's counts say?)",
                short(line)
            )));
        }
        Ok(())
    }

    fn skip_section(&mut self, header: &str) -> Result<()> {
        let want = format!("$End{}", &header[1..]);
        let hay = &self.b[self.pos..];
        let k = hay
            .windows(want.len())
            .position(|w| w == want.as_bytes())
            .ok_or_else(|| self.err(format!("the file ends inside {header} (truncated?)")))?;
        self.line += hay[..k].iter().filter(|&&c| c == b'\n').count();
        self.pos += k;
        self.rest_of_line()?;
        Ok(())
    }

    /// An ASCII token.
    fn token(&mut self) -> Result<&'a str> {
        self.skip_ws();
        let start = self.pos;
        while self.pos < self.b.len() && !self.b[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        if start == self.pos {
            return Err(self.truncated());
        }
        std::str::from_utf8(&self.b[start..self.pos]).map_err(|_| self.err("invalid text"))
    }

    fn parse<T: std::str::FromStr>(&mut self, what: &str) -> Result<T> {
        let t = self.token()?;
        t.parse()
            .map_err(|_| self.err(format!("expected {what}, found '{}'", short(t))))
    }

    fn raw<const N: usize>(&mut self) -> Result<[u8; N]> {
        let s = self
            .b
            .get(self.pos..self.pos + N)
            .ok_or_else(|| self.truncated())?;
        self.pos += N;
        Ok(s.try_into().expect("N bytes"))
    }

    /// A size_t (binary) or unsigned integer (ASCII).
    fn size(&mut self, what: &str) -> Result<u64> {
        if self.binary {
            Ok(u64::from_le_bytes(self.raw()?))
        } else {
            self.parse(what)
        }
    }

    /// An int (binary) or integer (ASCII).
    fn int(&mut self, what: &str) -> Result<i64> {
        if self.binary {
            Ok(i32::from_le_bytes(self.raw()?) as i64)
        } else {
            self.parse(what)
        }
    }

    fn real(&mut self, what: &str) -> Result<f64> {
        if self.binary {
            Ok(f64::from_le_bytes(self.raw()?))
        } else {
            self.parse(what)
        }
    }

    /// Refuses a count of items of at least `min_bytes` each that the rest of the file
    /// cannot hold (so nothing is allocated for sizes the file does not have).
    fn check_count(&self, count: u64, min_bytes: u64, what: &str) -> Result<usize> {
        let left = (self.b.len() - self.pos) as u64;
        if count.saturating_mul(min_bytes) > left {
            return Err(self.err(format!(
                "{count} {what} announced but only {left} bytes remain (truncated or corrupt)"
            )));
        }
        Ok(count as usize)
    }

    fn mesh_format(&mut self) -> Result<()> {
        let version = self.token()?;
        if version != "4.1" {
            return Err(self.err(format!(
                "MSH version {version} is not supported; save as version 4.1 (gmsh -format msh41)"
            )));
        }
        let file_type: u32 = self.parse("the file type (0 ASCII, 1 binary)")?;
        let data_size: u32 = self.parse("the data size")?;
        if data_size != 8 {
            return Err(self.err(format!(
                "data size {data_size} is not supported (only 8-byte size_t)"
            )));
        }
        match file_type {
            0 => {}
            1 => {
                // One int 1 written in the file's byte order, right after the line end.
                self.rest_of_line()?;
                self.binary = true;
                let one = i32::from_le_bytes(self.raw()?);
                if one != 1 {
                    return Err(self.err("big-endian binary files are not supported"));
                }
                self.binary = false;
            }
            t => return Err(self.err(format!("unknown file type {t}"))),
        }
        self.binary = file_type == 1;
        Ok(())
    }

    fn nodes(&mut self) -> Result<Nodes> {
        let blocks = self.size("the number of entity blocks")?;
        let total = self.size("the number of nodes")?;
        let _min = self.size("the smallest node tag")?;
        let _max = self.size("the largest node tag")?;
        let min_node = if self.binary { 32 } else { 8 };
        let total = self.check_count(total, min_node, "nodes")?;
        let blocks = self.check_count(blocks, if self.binary { 20 } else { 8 }, "node blocks")?;
        let mut tags = Vec::with_capacity(total);
        let mut coords = Vec::with_capacity(total);
        for _ in 0..blocks {
            let dim = self.int("the entity dimension")?;
            let _entity = self.int("the entity tag")?;
            let parametric = self.int("the parametric flag")?;
            let n = self.size("the number of nodes in the block")?;
            let n = self.check_count(n, min_node, "nodes in a block")?;
            if tags.len() + n > total {
                return Err(self.err(format!(
                    "the blocks hold more than the {total} nodes announced"
                )));
            }
            let extra = if parametric != 0 { dim.clamp(0, 3) } else { 0 } as usize;
            for _ in 0..n {
                tags.push(self.size("a node tag")?);
            }
            for _ in 0..n {
                let x = self.real("a coordinate")?;
                let y = self.real("a coordinate")?;
                let z = self.real("a coordinate")?;
                for _ in 0..extra {
                    self.real("a parametric coordinate")?;
                }
                coords.push(DVec3::new(x, y, z));
            }
        }
        if tags.len() != total {
            return Err(self.err(format!(
                "the blocks hold {} nodes, {total} announced",
                tags.len()
            )));
        }
        Ok(Nodes { tags, coords })
    }

    fn elements(&mut self) -> Result<Elements> {
        let blocks = self.size("the number of entity blocks")?;
        let total = self.size("the number of elements")?;
        let _min = self.size("the smallest element tag")?;
        let _max = self.size("the largest element tag")?;
        // Smallest number: 8 bytes binary, a digit and a separator in ASCII.
        let min_number = if self.binary { 8 } else { 2 };
        self.check_count(total, 2 * min_number, "elements")?;
        let blocks =
            self.check_count(blocks, if self.binary { 20 } else { 8 }, "element blocks")?;
        let mut out = Elements {
            tags: Vec::new(),
            types: Vec::new(),
            offsets: vec![0],
            nodes: Vec::new(),
            skipped_lower: 0,
        };
        let mut seen = 0u64;
        for _ in 0..blocks {
            let dim = self.int("the entity dimension")?;
            let _entity = self.int("the entity tag")?;
            let ty = self.int("the element type")?;
            let n = self.size("the number of elements in the block")?;
            let block_at = self.where_();
            let &(_, type_name, type_dim, count) = u32::try_from(ty)
                .ok()
                .and_then(|t| ELEMENT_TYPES.iter().find(|e| e.0 == t))
                .ok_or_else(|| self.err(unknown_type(ty)))?;
            let count = count as usize;
            let n = self.check_count(n, min_number * (1 + count as u64), "elements in a block")?;
            seen += n as u64;
            if seen > total {
                return Err(self.err(format!(
                    "the blocks hold more than the {total} elements announced"
                )));
            }
            let volume = VOLUME_TYPES.iter().position(|v| v.ty == ty as u32);
            if volume.is_none() {
                if type_dim == 3 || dim == 3 {
                    // The incomplete cells' remedy is a gmsh option; a pyramid has none.
                    let remedy = if type_name.contains("Pyramid") {
                        "pyramids are not read: mesh without them (no recombination into \
                         hexahedra next to tetrahedra)"
                    } else {
                        "for higher orders, set Mesh.SecondOrderIncomplete = 0"
                    };
                    return Err(self.err(format!(
                        "{block_at}: elements of type {ty} ({type_name}) are not supported; \
                         only complete Lagrange tetrahedra, hexahedra and prisms (orders gmsh \
                         describes) and the second-order incomplete hexahedra and prisms are \
                         ({remedy})"
                    )));
                }
                out.skipped_lower += n;
                for _ in 0..n * (1 + count) {
                    self.size("an element tag or node tag")?;
                }
                continue;
            }
            for _ in 0..n {
                let tag = self.size("an element tag")?;
                for _ in 0..count {
                    let node = self.size("a node tag")?;
                    out.nodes.push(node);
                }
                out.tags.push(tag);
                out.types.push(volume.expect("checked"));
                out.offsets.push(out.nodes.len());
            }
        }
        if seen != total {
            return Err(self.err(format!(
                "the blocks hold {seen} elements, {total} announced"
            )));
        }
        Ok(out)
    }

    fn where_(&self) -> String {
        if self.binary {
            format!("block at byte {}", self.pos)
        } else {
            format!("block on line {}", self.line)
        }
    }

    fn node_data(&mut self) -> Result<NodeData> {
        // Tags are text lines even in binary files.
        let was_binary = std::mem::replace(&mut self.binary, false);
        let strings: usize = self.parse("the number of string tags")?;
        self.rest_of_line()?;
        let mut name = String::new();
        for k in 0..strings.min(64) {
            let line = self.rest_of_line()?;
            if k == 0 {
                name = line.trim_matches('"').to_string();
            }
        }
        let reals: usize = self.parse("the number of real tags")?;
        for _ in 0..reals.min(64) {
            self.parse::<f64>("a real tag")?;
        }
        let ints: usize = self.parse("the number of integer tags")?;
        let mut int_tags = Vec::new();
        for _ in 0..ints.min(64) {
            int_tags.push(self.parse::<i64>("an integer tag")?);
        }
        if int_tags.len() < 3 {
            return Err(self.err(format!(
                "field '{name}': {} integer tags, need time step, components and count",
                int_tags.len()
            )));
        }
        let (step, components, count) = (int_tags[0], int_tags[1], int_tags[2]);
        if !(1..=9).contains(&components) || count < 0 {
            return Err(self.err(format!(
                "field '{name}': {components} components and {count} values are not valid"
            )));
        }
        let components = components as usize;
        if was_binary {
            self.rest_of_line()?;
        }
        self.binary = was_binary;
        let per = if self.binary {
            4 + 8 * components
        } else {
            2 * (1 + components)
        };
        let count = self.check_count(count as u64, per as u64, "node values")?;
        let mut tags = Vec::with_capacity(count);
        let mut values = Vec::with_capacity(count * components);
        for _ in 0..count {
            let tag = self.int("a node tag")?;
            tags.push(u64::try_from(tag).map_err(|_| self.err(format!("node tag {tag}")))?);
            for _ in 0..components {
                values.push(self.real("a value")?);
            }
        }
        Ok(NodeData {
            name,
            step,
            components,
            tags,
            values,
        })
    }
}

/// Why element type `ty` is not in gmsh's table of types it describes: one gmsh numbers
/// but cannot describe (prisms above order 2), or one it does not know at all.
fn unknown_type(ty: i64) -> String {
    let Some(u) = UNDESCRIBED_TYPES.iter().find(|u| i64::from(u.ty) == ty) else {
        return format!("unknown element type {ty}");
    };
    let family = match u.kind {
        Kind::Hexahedron => "hexahedra",
        Kind::Tetrahedron => "tetrahedra",
        Kind::Wedge => "prisms",
    };
    let described = VOLUME_TYPES
        .iter()
        .filter(|v| v.kind == u.kind)
        .map(|v| v.order)
        .max()
        .unwrap_or(0);
    format!(
        "element type {ty} ({}{family} of order {}) cannot be read: gmsh itself has no \
         node-ordering definition for {family} above order {described} (gmsh {GMSH_VERSION}'s \
         getElementProperties({ty}) fails with \"{}\"), so their nodes cannot be matched to \
         VTK's; mesh with {family} of order {described} or lower, or with tetrahedra or \
         hexahedra",
        if u.serendipity { "incomplete " } else { "" },
        u.order,
        u.gmsh_error
    )
}

fn short(s: &str) -> String {
    s.chars().take(40).collect()
}

/// The VTK position of each gmsh node of a volume type (gmsh node k is VTK node perm[k]).
fn permutation(ty: usize) -> Vec<usize> {
    let v = &VOLUME_TYPES[ty];
    let vtk: FxHashMap<glam::IVec3, usize> = match classic::serendipity(v.kind) {
        // VTK's quadratic serendipity cell's own node order (the mesh completes it).
        Some((_, nodes)) if v.serendipity => nodes
            .iter()
            .enumerate()
            .map(|(n, g)| (glam::IVec3::new(g[0] as i32, g[1] as i32, g[2] as i32), n))
            .collect(),
        _ => {
            let shape = Shape::new(v.kind, [v.order; 3]);
            let key = |u: DVec3| (u * v.order as f64).round().as_ivec3();
            (0..shape.len())
                .map(|n| (key(shape.node_coords(n)), n))
                .collect()
        }
    };
    v.lattice
        .iter()
        .map(|l| vtk[&glam::IVec3::new(l[0] as i32, l[1] as i32, l[2] as i32)])
        .collect()
}

fn assemble(name: &str, nodes: Nodes, elements: Elements, data: Vec<NodeData>) -> Result<FeMesh> {
    if elements.tags.is_empty() {
        return Err(Error::format(
            name,
            format!(
                "no volume elements (tetrahedra, hexahedra, prisms); {} lower-dimensional elements skipped",
                elements.skipped_lower
            ),
        ));
    }
    let mut index: FxHashMap<u64, u32> = FxHashMap::default();
    index.reserve(nodes.tags.len());
    for (i, &t) in nodes.tags.iter().enumerate() {
        if index.insert(t, i as u32).is_some() {
            return Err(Error::format(
                name,
                format!("$Nodes: node tag {t} appears twice"),
            ));
        }
    }
    // Only nodes of volume elements become points, numbered in file order.
    let mut used = vec![u32::MAX; nodes.tags.len()];
    for (e, &tag) in elements.tags.iter().enumerate() {
        for &n in &elements.nodes[elements.offsets[e]..elements.offsets[e + 1]] {
            let i = *index.get(&n).ok_or_else(|| {
                Error::format(
                    name,
                    format!(
                        "$Elements: element {tag} refers to node {n}, which $Nodes does not have"
                    ),
                )
            })?;
            used[i as usize] = 0;
        }
    }
    let mut points = Vec::new();
    for (i, u) in used.iter_mut().enumerate() {
        if *u == 0 {
            *u = points.len() as u32;
            points.push(nodes.coords[i]);
        }
    }
    let perms: Vec<Vec<usize>> = (0..VOLUME_TYPES.len()).map(permutation).collect();
    let mut types = Vec::with_capacity(elements.tags.len());
    let mut offsets = vec![0usize];
    let mut connectivity = Vec::with_capacity(elements.nodes.len());
    for e in 0..elements.tags.len() {
        let ty = elements.types[e];
        let gmsh = &elements.nodes[elements.offsets[e]..elements.offsets[e + 1]];
        let mut vtk = vec![0u32; gmsh.len()];
        for (k, &n) in gmsh.iter().enumerate() {
            vtk[perms[ty][k]] = used[index[&n] as usize];
        }
        connectivity.extend(vtk);
        let v = &VOLUME_TYPES[ty];
        types.push(match classic::serendipity(v.kind) {
            Some((vtk, _)) if v.serendipity => vtk,
            _ => v.kind.vtk_type(),
        });
        offsets.push(connectivity.len());
    }
    // The last time step of each field name.
    let mut point_data: Vec<Attribute> = Vec::new();
    let mut chosen: Vec<&NodeData> = Vec::new();
    for d in &data {
        match chosen.iter_mut().find(|c| c.name == d.name) {
            Some(c) if d.step >= c.step => *c = d,
            Some(_) => {}
            None => chosen.push(d),
        }
    }
    for d in chosen {
        let c = d.components;
        let mut values = vec![f64::NAN; points.len() * c];
        for (k, &t) in d.tags.iter().enumerate() {
            if let Some(&i) = index.get(&t) {
                let p = used[i as usize];
                if p != u32::MAX {
                    values[p as usize * c..(p as usize + 1) * c]
                        .copy_from_slice(&d.values[k * c..(k + 1) * c]);
                }
            }
        }
        if let Some(p) = values.iter().position(|v| v.is_nan()) {
            let point = p / c;
            let tag = nodes.tags[used.iter().position(|&u| u == point as u32).unwrap_or(0)];
            return Err(Error::format(
                name,
                format!(
                    "$NodeData '{}' (time step {}): no value for node {tag}, which a volume element uses",
                    d.name, d.step
                ),
            ));
        }
        point_data.push(Attribute {
            name: d.name.clone(),
            components: c,
            data: values,
        });
    }
    let mesh = FeMesh::new(
        name,
        points,
        &types,
        &offsets,
        connectivity,
        None,
        point_data,
    );
    // FeMesh names cells by index; add the gmsh element tag.
    mesh.map_err(|e| match e {
        Error::InvalidInput(m) => Error::InvalidInput(name_element(&m, &elements.tags)),
        e => e,
    })
}

/// Appends the gmsh element tag to a message that names "cell N".
fn name_element(message: &str, tags: &[u64]) -> String {
    let cell = message
        .split("cell ")
        .nth(1)
        .and_then(|s| s.split(|c: char| !c.is_ascii_digit()).next())
        .and_then(|s| s.parse::<usize>().ok());
    match cell.and_then(|c| tags.get(c)) {
        Some(t) => format!("{message} (gmsh element {t})"),
        None => message.to_string(),
    }
}
