//! Particle readers and mesh writers.
//!
//! Readers turn a file (or bytes in memory) into [`ParticleData`] with every value converted
//! to f64; the format is chosen by the file extension. Writers turn a [`Mesh`] into a file
//! atomically (temporary sibling + rename). Every error names the file and what is wrong,
//! and no input, however broken, makes a reader panic or allocate for sizes the file does
//! not actually hold.
//!
//! | extension | read particles | write / read mesh |
//! | --- | --- | --- |
//! | `.vtk` | legacy VTK, ASCII or BINARY | |
//! | `.vtu`, `.vtp` | VTK XML (ascii, base64, appended, zlib) | `.vtp` |
//! | `.vtu` (Lagrange cells) | finite elements: [`read_fe_mesh`] | |
//! | `.msh` (Gmsh 4.1, ASCII or binary) | finite elements: [`read_fe_mesh`] | |
//! | `.ply` | ascii and binary | binary little endian |
//! | `.obj` | | yes |
//! | `.bgeo` | Houdini classic geometry (gzip or not) | |
//! | `.csv`, `.xyz` | text columns | |
//! | `.npy`, `.npz` | NumPy arrays | |
//!
//! Any particle file may additionally be gzip-compressed (`frame.vtk.gz`, or detected by its
//! magic bytes).

mod atomic;
mod bgeo;
mod csv;
mod gmsh;
mod npy;
mod numeric;
mod obj;
mod ply;
mod sequence;
mod spool;
pub mod volume;
mod vtk_legacy;
mod vtk_xml;

#[cfg(test)]
mod test_support;

use crate::error::{Error, Result};
use crate::field::particles::ParticleData;
use crate::mesh::Mesh;
use glam::DVec3;
use std::io::Read;
use std::path::Path;

pub use atomic::check_writable as check_output;
/// Crash-safe replacement of a file (temporary sibling + rename), for other modules' writers.
pub(crate) use atomic::{open_regular, parent_dir, read_regular_file, write_atomically};
pub use sequence::{
    check_frame_outputs, expand_sequence, fill_frame, frame_number, frame_output, frames_for,
    missing_frames, print_warnings, warn_if_gaps,
};
pub(crate) use spool::Spool;
pub use volume::{read_volume, RawLayout, RawType, VOLUME_EXTENSIONS};

/// Extensions [`read_particles`] understands (each may also carry a trailing `.gz`).
pub const PARTICLE_EXTENSIONS: &[&str] = &[
    "vtk", "vtu", "vtp", "ply", "bgeo", "csv", "xyz", "npy", "npz",
];

/// Extensions [`write_mesh`] writes and [`read_mesh`] reads back.
pub const MESH_EXTENSIONS: &[&str] = &["ply", "obj", "vtp"];

/// Reads particle positions and every per-particle array from `path`, choosing the format by
/// the (case-insensitive) extension; see the module table.
pub fn read_particles(path: &Path) -> Result<ParticleData> {
    let format = extension_of(path);
    if format.is_empty() {
        return Err(unknown_particle_format(&path.display().to_string(), ""));
    }
    let bytes = read_regular_file(path)?;
    read_particles_from_bytes(&bytes, &format, &path.display().to_string())
}

/// Reads particles from bytes in memory. `format_extension` is the extension the bytes would
/// have as a file (`"npz"`, `".vtk"`, `"bgeo.gz"`; any case); `name_for_errors` is what error
/// messages call the data.
pub fn read_particles_from_bytes(
    bytes: &[u8],
    format_extension: &str,
    name_for_errors: &str,
) -> Result<ParticleData> {
    let name = name_for_errors;
    let format = format_extension
        .trim_start_matches('.')
        .to_ascii_lowercase();
    let format = format.strip_suffix(".gz").unwrap_or(&format);
    if !PARTICLE_EXTENSIONS.contains(&format) {
        return Err(unknown_particle_format(name, format));
    }
    if bytes.is_empty() {
        return Err(Error::format(name, "the file is empty"));
    }
    let unpacked;
    let bytes = if is_gzip(bytes) {
        unpacked = gunzip(bytes, name)?;
        &unpacked[..]
    } else {
        bytes
    };
    match format {
        "vtk" => vtk_legacy::read(bytes, name),
        "vtu" | "vtp" => vtk_xml::read_particles(bytes, name),
        "ply" => ply::read_particles(bytes, name),
        "bgeo" => bgeo::read(bytes, name),
        "csv" => csv::read_csv(bytes, name),
        "xyz" => csv::read_xyz(bytes, name),
        "npy" => npy::read_npy(bytes, name),
        "npz" => npy::read_npz(bytes, name),
        _ => Err(unknown_particle_format(name, format)),
    }
}

/// Writes `mesh` to `path` in the format of its extension (`.ply` binary, `.obj`, `.vtp`).
/// The file is written to a hidden temporary sibling and renamed into place, so an
/// interrupted or failed write leaves any previous file as it was.
pub fn write_mesh(path: &Path, mesh: &Mesh) -> Result<()> {
    let write = mesh_writer(path)?;
    check_mesh(mesh, &path.display().to_string())?;
    atomic::write_atomically(path, |w| write(w, mesh))
}

/// Writes a mesh in one format.
type MeshWriter = fn(&mut dyn std::io::Write, &Mesh) -> std::io::Result<()>;

/// The writer of `path`'s mesh format, by its extension.
fn mesh_writer(path: &Path) -> Result<MeshWriter> {
    match extension_of(path).as_str() {
        "ply" => Ok(ply::write_mesh),
        "obj" => Ok(obj::write_mesh),
        "vtp" => Ok(vtk_xml::write_mesh),
        "" => Err(Error::format(
            path,
            format!(
                "no extension to name the mesh format; supported: {}",
                list(MESH_EXTENSIONS)
            ),
        )),
        format => Err(Error::format(
            path,
            format!(
                "cannot write a mesh as '.{format}'; supported: {}",
                list(MESH_EXTENSIONS)
            ),
        )),
    }
}

/// Checks before an extraction that [`write_mesh`] can write to `path` (its extension
/// names a mesh format, its folder takes a file), so a long run does not end in an error
/// the path alone would have given.
pub fn check_mesh_output(path: &Path) -> Result<()> {
    mesh_writer(path)?;
    check_output(path)
}

/// [`check_mesh_output`] for [`write_samples`].
pub fn check_samples_output(path: &Path) -> Result<()> {
    samples_format(path)?;
    check_output(path)
}

fn samples_format(path: &Path) -> Result<()> {
    let format = extension_of(path);
    if format != "vtp" {
        return Err(Error::format(
            path,
            format!("cannot write point samples as '.{format}'; supported: .vtp"),
        ));
    }
    Ok(())
}

/// Reads a mesh written by [`write_mesh`] (and ordinary PLY, VTP and OBJ triangle or polygon
/// meshes; polygons are split into triangle fans). Tools and tests use it to read outputs back.
pub fn read_mesh(path: &Path) -> Result<Mesh> {
    let format = extension_of(path);
    let name = path.display().to_string();
    if !MESH_EXTENSIONS.contains(&format.as_str()) {
        return Err(Error::format(
            path,
            format!(
                "cannot read a mesh from '.{format}'; supported: {}",
                list(MESH_EXTENSIONS)
            ),
        ));
    }
    let bytes = read_regular_file(path)?;
    if bytes.is_empty() {
        return Err(Error::format(path, "the file is empty"));
    }
    let mesh = match format.as_str() {
        "ply" => ply::read_mesh(&bytes, &name)?,
        "obj" => obj::read_mesh(&bytes, &name)?,
        _ => vtk_xml::read_mesh(&bytes, &name)?,
    };
    check_mesh(&mesh, &name)?;
    Ok(mesh)
}

/// Writes oriented point samples as `.vtp` (vertex cells with Normals, Radius and every
/// array), atomically like [`write_mesh`].
pub fn write_samples(path: &Path, samples: &crate::samples::PointSamples) -> Result<()> {
    samples_format(path)?;
    let n = samples.len();
    if samples.normals.len() != n
        || samples.radii.len() != n
        || samples
            .attributes
            .iter()
            .any(|a| a.data.len() != n * a.components)
    {
        return Err(Error::InvalidInput(format!(
            "{}: point samples with arrays of inconsistent lengths",
            path.display()
        )));
    }
    atomic::write_atomically(path, |w| vtk_xml::write_points(w, samples))
}

/// Reads high-order finite elements: a `.vtu` UnstructuredGrid with Lagrange hexahedra,
/// tetrahedra and wedges (VTK types 72, 71, 73) or VTK's linear and quadratic volume cells
/// (see `field::fe::classic`) and its point arrays, or a Gmsh `.msh`
/// 4.1 file with Lagrange tetrahedra, hexahedra and prisms and its `$NodeData`. Every cell is checked
/// (node count, point indices, det J > 0) and a failure names the cell.
pub fn read_fe_mesh(path: &Path) -> Result<crate::field::fe::FeMesh> {
    let format = extension_of(path);
    if format != "vtu" && format != "msh" {
        return Err(Error::format(
            path,
            format!("cannot read finite elements from '.{format}'; supported: .vtu, .msh"),
        ));
    }
    let bytes = read_regular_file(path)?;
    if bytes.is_empty() {
        return Err(Error::format(path, "the file is empty"));
    }
    let name = path.display().to_string();
    if format == "msh" {
        gmsh::read_fe_mesh(&bytes, &name)
    } else {
        vtk_xml::read_fe_mesh(&bytes, &name)
    }
}

/// Lower-case extension; for `x.bgeo.gz` it is `bgeo.gz` so that the inner format is known.
fn extension_of(path: &Path) -> String {
    let ext = |p: &Path| {
        p.extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default()
    };
    let outer = ext(path);
    if outer == "gz" {
        if let Some(stem) = path.file_stem() {
            let inner = ext(Path::new(stem));
            if !inner.is_empty() {
                return format!("{inner}.gz");
            }
        }
    }
    outer
}

fn list(extensions: &[&str]) -> String {
    extensions
        .iter()
        .map(|e| format!(".{e}"))
        .collect::<Vec<_>>()
        .join(", ")
}

fn unknown_particle_format(name: &str, format: &str) -> Error {
    let what = if format.is_empty() {
        "no file extension to tell the format".to_string()
    } else {
        format!("unknown particle file format '.{format}'")
    };
    Error::format(
        name,
        format!("{what}; supported: {}", list(PARTICLE_EXTENSIONS)),
    )
}

fn is_gzip(bytes: &[u8]) -> bool {
    bytes.starts_with(&[0x1f, 0x8b])
}

/// Deflate cannot shrink data by more than about 1032:1, so a decompressed size beyond this
/// bound means a corrupt or hostile stream, refused before it fills memory.
pub(crate) fn inflate_bound(compressed_len: usize) -> usize {
    compressed_len.saturating_mul(1040).saturating_add(4096)
}

fn gunzip(bytes: &[u8], name: &str) -> Result<Vec<u8>> {
    let limit = inflate_bound(bytes.len());
    let mut out = Vec::with_capacity(bytes.len().saturating_mul(4));
    flate2::read::MultiGzDecoder::new(bytes)
        .take(limit as u64 + 1)
        .read_to_end(&mut out)
        .map_err(|e| Error::format(name, format!("corrupt gzip compression: {e}")))?;
    if out.len() > limit {
        return Err(Error::format(
            name,
            "gzip data expands beyond what deflate can produce (corrupt file)",
        ));
    }
    if out.is_empty() {
        return Err(Error::format(name, "the gzip-compressed file is empty"));
    }
    Ok(out)
}

/// Positions from item-major `x y z` triples.
fn positions_from_flat(flat: &[f64]) -> Vec<DVec3> {
    flat.chunks_exact(3)
        .map(|c| DVec3::new(c[0], c[1], c[2]))
        .collect()
}

/// A mesh must be self-consistent before it is written (an index past the vertices would make
/// a file no viewer can load) and after it is read.
fn check_mesh(mesh: &Mesh, name: &str) -> Result<()> {
    let n = mesh.positions.len();
    if !mesh.normals.is_empty() && mesh.normals.len() != n {
        return Err(Error::InvalidInput(format!(
            "{name}: mesh has {} normals for {n} vertices",
            mesh.normals.len()
        )));
    }
    if let Some((t, tri)) = mesh
        .triangles
        .iter()
        .enumerate()
        .find(|(_, t)| t.iter().any(|&i| i as usize >= n))
    {
        return Err(Error::InvalidInput(format!(
            "{name}: triangle {t} {tri:?} refers to a vertex past the {n} vertices"
        )));
    }
    for a in &mesh.attributes {
        if a.components == 0 || Some(a.data.len()) != n.checked_mul(a.components) {
            return Err(Error::InvalidInput(format!(
                "{name}: mesh attribute '{}' has {} values for {n} vertices with {} components",
                a.name,
                a.data.len(),
                a.components
            )));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::test_support::*;
    use super::*;
    use crate::field::particles::Attribute;

    #[test]
    fn unknown_extension_lists_supported_ones() {
        let err = read_particles_from_bytes(b"abc", "foo", "x.foo").unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.contains("x.foo") && msg.contains(".vtk") && msg.contains(".npz"),
            "{msg}"
        );
        let err = read_particles(Path::new("no_extension")).unwrap_err();
        assert!(err.to_string().contains("supported"), "{err}");
        let err = write_mesh(Path::new("/tmp/out.stl"), &Mesh::default()).unwrap_err();
        assert!(err.to_string().contains(".ply"), "{err}");
    }

    #[test]
    fn empty_and_missing_files_are_errors() {
        let err = read_particles_from_bytes(b"", "vtk", "e.vtk").unwrap_err();
        assert!(
            err.to_string().contains("e.vtk: the file is empty"),
            "{err}"
        );
        let err = read_particles(Path::new("/nonexistent/frame.vtk")).unwrap_err();
        assert!(matches!(err, Error::Io { .. }), "{err}");
        assert!(err.to_string().contains("frame.vtk"));
    }

    #[test]
    fn gzip_is_detected_for_any_format() {
        use std::io::Write;
        let csv = b"x,y,z,rho\n1,2,3,4\n5,6,7,8\n";
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        gz.write_all(csv).unwrap();
        let gz = gz.finish().unwrap();
        let p = read_particles_from_bytes(&gz, "csv.gz", "p.csv.gz").unwrap();
        assert_eq!(p.len(), 2);
        assert_eq!(p.attribute("rho").unwrap().data, vec![4.0, 8.0]);
        let err = read_particles_from_bytes(&gz[..gz.len() / 2], "csv", "p.csv").unwrap_err();
        assert!(err.to_string().contains("p.csv"), "{err}");
        assert_eq!(
            extension_of(Path::new("/a/Frame_01.BGEO.gz")),
            "bgeo.gz".to_string()
        );
    }

    #[test]
    fn every_shared_data_file_reads() {
        for (path, expected) in shared_data_files() {
            let p = read_particles(&path).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(p.len(), expected, "{}", path.display());
            check_sane(&p, &path.display().to_string());
        }
    }

    #[test]
    fn writers_refuse_inconsistent_meshes_and_keep_no_temporary() {
        let dir = scratch_dir("write-check");
        let path = dir.join("bad.ply");
        let mut mesh = sample_mesh();
        mesh.triangles.push([0, 1, 99]);
        let err = write_mesh(&path, &mesh).unwrap_err();
        assert!(err.to_string().contains("99"), "{err}");
        assert!(!path.exists());
        let mut mesh = sample_mesh();
        mesh.attributes.push(Attribute::scalar("short", vec![1.0]));
        assert!(write_mesh(&path, &mesh).is_err());

        for ext in MESH_EXTENSIONS {
            let path = dir.join(format!("ok.{ext}"));
            write_mesh(&path, &sample_mesh()).unwrap();
            write_mesh(&path, &sample_mesh()).unwrap();
        }
        let names: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert!(names.iter().all(|n| !n.starts_with('.')), "{names:?}");
        assert_eq!(names.len(), MESH_EXTENSIONS.len(), "{names:?}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
