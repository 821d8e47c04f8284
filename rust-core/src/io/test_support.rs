//! Fixtures shared by the io unit tests: the real particle files in shared/, a small mesh,
//! scratch folders, and the "no truncation may panic" check.

use crate::field::particles::{Attribute, ParticleData};
use crate::mesh::Mesh;
use std::path::PathBuf;

/// The splashsurf sample frames shipped with the project.
pub(crate) fn shared_data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/splashsurf")
}

/// Every particle file in the shared data folder with the number of particles it holds.
/// The count is the one in the file name, except where the name is wrong (see below).
pub(crate) fn shared_data_files() -> Vec<(PathBuf, usize)> {
    let mut files: Vec<(PathBuf, usize)> = std::fs::read_dir(shared_data_dir())
        .expect("shared/data/splashsurf is missing")
        .map(|e| e.unwrap().path())
        .filter(|p| {
            let ext = p.extension().map(|e| e.to_string_lossy().to_string());
            matches!(ext.as_deref(), Some("vtk" | "vtu" | "bgeo"))
        })
        .map(|p| {
            let stem = p.file_stem().unwrap().to_string_lossy().to_string();
            let mut parts = stem.rsplit('_');
            assert_eq!(parts.next(), Some("particles"), "{stem}");
            let mut n: usize = parts.next().unwrap().parse().unwrap();
            // The bunny frame's name says 7705, but its POINTS, CELLS and POINT_DATA headers
            // and its data all hold 7706 particles.
            if stem == "bunny_frame_14_7705_particles" {
                n = 7706;
            }
            (p, n)
        })
        .collect();
    files.sort();
    assert!(
        files.len() >= 13,
        "expected the 13 sample frames, found {}",
        files.len()
    );
    files
}

/// Finite positions in a box no sample exceeds, and arrays as long as the positions.
pub(crate) fn check_sane(p: &ParticleData, name: &str) {
    p.validate().unwrap_or_else(|e| panic!("{name}: {e}"));
    let (mut lo, mut hi) = (glam::DVec3::splat(f64::MAX), glam::DVec3::splat(f64::MIN));
    for x in &p.positions {
        lo = lo.min(*x);
        hi = hi.max(*x);
    }
    let extent = hi - lo;
    assert!(
        extent.max_element() > 1e-3,
        "{name}: all particles in one spot {lo} {hi}"
    );
    assert!(
        lo.min_element() > -1e3 && hi.max_element() < 1e3,
        "{name}: bounding box {lo} {hi}"
    );
}

/// A fresh empty folder under the system temporary directory.
pub(crate) fn scratch_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("isobar-io-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A closed tetrahedron with normals, a scalar and a vector attribute, and coordinates that
/// need all of f64 to be kept exactly.
pub(crate) fn sample_mesh() -> Mesh {
    let third = 1.0 / 3.0;
    let positions = vec![
        [0.0, 0.0, 0.0],
        [1.0 + 1e-12, 0.0, 0.0],
        [0.0, third, 0.0],
        [0.1, 0.2, 0.7 + 1e-15],
    ];
    let normals = positions
        .iter()
        .map(|p: &[f64; 3]| {
            let v = glam::DVec3::from(*p) - glam::DVec3::splat(0.25);
            v.normalize().as_vec3().to_array()
        })
        .collect();
    Mesh {
        positions,
        normals,
        triangles: vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
        attributes: vec![
            Attribute::scalar("SumOfWeights", vec![0.6, 0.61, 0.599, third]),
            Attribute::vector(
                "velocity",
                vec![
                    [1.0, 2.0, 3.0],
                    [-1.0, 0.5, 0.25],
                    [0.0, 0.0, 0.0],
                    [9.0, 8.0, 7.0],
                ],
            ),
        ],
    }
}

/// Cuts `bytes` at several places (in half among them) and requires every cut to
/// give an error naming the file, never a panic and never a silent success with fewer items
/// than the whole file has.
pub(crate) fn assert_truncations_fail(bytes: &[u8], ext: &str, name: &str, full_len: usize) {
    for cut in [bytes.len() / 2, bytes.len() * 9 / 10, 1, bytes.len() / 7] {
        match super::read_particles_from_bytes(&bytes[..cut], ext, name) {
            Err(e) => assert!(e.to_string().contains(name), "{e}"),
            Ok(p) => panic!(
                "{name} cut to {cut} of {} bytes read as {} of {full_len} particles",
                bytes.len(),
                p.len()
            ),
        }
    }
}

/// For formats without declared counts (CSV, XYZ) a cut at a line end is a valid shorter file;
/// what must hold is that no cut, anywhere, panics.
pub(crate) fn assert_no_cut_panics(bytes: &[u8], ext: &str, name: &str) {
    let step = (bytes.len() / 97).max(1);
    for cut in (0..bytes.len()).step_by(step) {
        if let Err(e) = super::read_particles_from_bytes(&bytes[..cut], ext, name) {
            assert!(e.to_string().contains(name), "{e}");
        }
    }
}
