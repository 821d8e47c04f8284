//! Tests of the VTK XML reader and the `.vtp` writer.

use super::super::test_support::*;
use super::super::{read_mesh as read_file, read_particles as read_path, write_mesh as write_file};
use super::document::find;
use super::*;
use base64::engine::general_purpose::STANDARD as B64;
use base64::Engine;
use std::io::Write;

#[test]
fn both_fluid_files_agree() {
    let dir = shared_data_dir();
    let a = read_path(&dir.join("fluid_250_particles.vtu")).unwrap();
    let b = read_path(&dir.join("fluid_encoded_250_particles.vtu")).unwrap();
    assert_eq!(a.len(), 250);
    assert_eq!(a.positions, b.positions);
    let names = |p: &ParticleData| {
        let mut n: Vec<String> = p.attributes.iter().map(|a| a.name.clone()).collect();
        n.sort();
        n
    };
    assert_eq!(names(&a), ["density", "index", "pressure", "velocity"]);
    assert_eq!(names(&a), names(&b));
    for x in &a.attributes {
        assert_eq!(Some(x), b.attribute(&x.name), "{}", x.name);
    }
    let index = a.require("index").unwrap();
    assert_eq!(index.data.first(), Some(&1.0));
    assert_eq!(a.require("velocity").unwrap().components, 3);
}

#[test]
fn truncated_shared_files_fail_cleanly() {
    for f in ["fluid_250_particles.vtu", "fluid_encoded_250_particles.vtu"] {
        let bytes = std::fs::read(shared_data_dir().join(f)).unwrap();
        assert_truncations_fail(&bytes, "vtu", f, 250);
        assert_no_cut_panics(&bytes, "vtu", f);
    }
}

/// How a synthetic file stores its arrays.
#[derive(Clone, Copy, Debug)]
struct Style {
    format: &'static str,
    base64_appended: bool,
    header64: bool,
    zlib: bool,
    big: bool,
    /// base64 the header and data as one stream (VTK does for uncompressed data).
    joint: bool,
}

/// One encoded array: the size header (plain or block table) and the payload.
fn block(style: Style, data: &[u8]) -> (Vec<u8>, Vec<u8>) {
    let int = |v: usize| -> Vec<u8> {
        match (style.header64, style.big) {
            (true, false) => (v as u64).to_le_bytes().to_vec(),
            (true, true) => (v as u64).to_be_bytes().to_vec(),
            (false, false) => (v as u32).to_le_bytes().to_vec(),
            (false, true) => (v as u32).to_be_bytes().to_vec(),
        }
    };
    if !style.zlib {
        return (int(data.len()), data.to_vec());
    }
    let bs = 40;
    let chunks: Vec<&[u8]> = data.chunks(bs).collect();
    let packed: Vec<Vec<u8>> = chunks
        .iter()
        .map(|c| {
            let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
            z.write_all(c).unwrap();
            z.finish().unwrap()
        })
        .collect();
    let last = data.len() % bs;
    let mut header = [int(chunks.len()), int(bs), int(last)].concat();
    for p in &packed {
        header.extend(int(p.len()));
    }
    (header, packed.concat())
}

fn b64(style: Style, header: &[u8], data: &[u8]) -> String {
    if style.joint {
        B64.encode([header, data].concat())
    } else {
        B64.encode(header) + &B64.encode(data)
    }
}

fn synthetic_vtu(style: Style, arrays: &[(&str, &str, usize, &[f64])]) -> Vec<u8> {
    let n = arrays[0].3.len() / 3;
    let order = if style.big {
        "BigEndian"
    } else {
        "LittleEndian"
    };
    let header = if style.header64 { "UInt64" } else { "UInt32" };
    let compressor = if style.zlib {
        " compressor=\"vtkZLibDataCompressor\""
    } else {
        ""
    };
    let mut xml = format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"{order}\" header_type=\"{header}\"{compressor}>\n<UnstructuredGrid><Piece NumberOfPoints=\"{n}\" NumberOfCells=\"0\">\n"
    );
    let mut appended: Vec<u8> = Vec::new();
    let mut section = "";
    for &(section_name, name, comps, values) in arrays {
        if section != section_name {
            if !section.is_empty() {
                xml += &format!("</{section}>\n");
            }
            section = section_name;
            xml += &format!("<{section}>\n");
        }
        let ty = if name == "id" { "Int32" } else { "Float64" };
        let bytes: Vec<u8> = values
            .iter()
            .flat_map(|&v| match (ty, style.big) {
                ("Int32", false) => (v as i32).to_le_bytes().to_vec(),
                ("Int32", true) => (v as i32).to_be_bytes().to_vec(),
                (_, false) => v.to_le_bytes().to_vec(),
                (_, true) => v.to_be_bytes().to_vec(),
            })
            .collect();
        let open =
            format!("<DataArray type=\"{ty}\" Name=\"{name}\" NumberOfComponents=\"{comps}\"");
        match style.format {
            "ascii" => {
                let text: Vec<String> = values.iter().map(|v| v.to_string()).collect();
                xml += &format!(
                    "{open} format=\"ascii\">\n{}\n</DataArray>\n",
                    text.join(" ")
                );
            }
            "binary" => {
                let (h, d) = block(style, &bytes);
                xml += &format!(
                    "{open} format=\"binary\">\n  {}\n</DataArray>\n",
                    b64(style, &h, &d)
                );
            }
            _ => {
                xml += &format!(
                    "{open} format=\"appended\" offset=\"{}\"/>\n",
                    appended.len()
                );
                let (h, d) = block(style, &bytes);
                if style.base64_appended {
                    appended.extend(b64(style, &h, &d).into_bytes());
                } else {
                    appended.extend(h);
                    appended.extend(d);
                }
            }
        }
    }
    xml += &format!("</{section}>\n</Piece></UnstructuredGrid>\n");
    let mut out = xml.into_bytes();
    if style.format == "appended" {
        let enc = if style.base64_appended {
            "base64"
        } else {
            "raw"
        };
        out.extend(format!("<AppendedData encoding=\"{enc}\">\n _").into_bytes());
        out.extend(appended);
        out.extend(b"\n</AppendedData>\n");
    }
    out.extend(b"</VTKFile>\n");
    out
}

#[test]
fn every_storage_variant_reads_the_same() {
    let points: Vec<f64> = (0..21).map(|i| i as f64 * 0.1 - 1.0).collect();
    let rho: Vec<f64> = (0..7).map(|i| 1000.0 + i as f64 * 0.5).collect();
    let vel: Vec<f64> = (0..14).map(|i| i as f64 * 0.25).collect();
    let ids: Vec<f64> = (0..7).map(|i| i as f64 - 3.0).collect();
    let arrays: [(&str, &str, usize, &[f64]); 4] = [
        ("Points", "Points", 3, &points),
        ("PointData", "rho", 1, &rho),
        ("PointData", "vel", 2, &vel),
        ("PointData", "id", 1, &ids),
    ];
    let mut styles = Vec::new();
    for format in ["ascii", "binary", "appended"] {
        for base64_appended in [false, true] {
            for header64 in [false, true] {
                for zlib in [false, true] {
                    for big in [false, true] {
                        for joint in [false, true] {
                            styles.push(Style {
                                format,
                                base64_appended,
                                header64,
                                zlib,
                                big,
                                joint,
                            });
                        }
                    }
                }
            }
        }
    }
    for style in styles {
        let file = synthetic_vtu(style, &arrays);
        let p = read_particles(&file, "s.vtu").unwrap_or_else(|e| panic!("{style:?}: {e}"));
        assert_eq!(p.len(), 7, "{style:?}");
        let flat: Vec<f64> = p.positions.iter().flat_map(|x| x.to_array()).collect();
        assert_eq!(flat, points, "{style:?}");
        assert_eq!(p.require("rho").unwrap().data, rho, "{style:?}");
        let v = p.require("vel").unwrap();
        assert_eq!((v.components, &v.data), (2, &vel), "{style:?}");
        assert_eq!(p.require("id").unwrap().data, ids, "{style:?}");
        if style.format != "ascii" {
            assert_truncations_fail(&file, "vtu", "s.vtu", 7);
        }
        assert_no_cut_panics(&file, "vtu", "s.vtu");
    }
}

#[test]
fn gigantic_declared_sizes_are_refused() {
    let t = std::time::Instant::now();
    let style = Style {
        format: "appended",
        base64_appended: false,
        header64: true,
        zlib: false,
        big: false,
        joint: true,
    };
    let pts = [0.0; 6];
    let file = synthetic_vtu(style, &[("Points", "Points", 3, &pts)]);
    let text = String::from_utf8_lossy(&file).replace(
        "NumberOfPoints=\"2\"",
        "NumberOfPoints=\"1000000000000000\"",
    );
    let e = read_particles(text.as_bytes(), "g.vtu")
        .unwrap_err()
        .to_string();
    assert!(e.contains("g.vtu: DataArray 'Points' holds 48 bytes, but its declared size needs 24000000000000000"), "{e}");
    // a size header claiming far more than is there
    let mut file = synthetic_vtu(style, &[("Points", "Points", 3, &pts)]);
    let at = find(&file, b"_").unwrap() + 1;
    file[at..at + 8].copy_from_slice(&u64::MAX.to_le_bytes());
    assert!(read_particles(&file, "h.vtu").is_err());
    for format in ["ascii", "binary"] {
        let style = Style {
            format,
            zlib: true,
            ..style
        };
        let file = synthetic_vtu(style, &[("Points", "Points", 3, &pts)]);
        let text = String::from_utf8_lossy(&file).replace(
            "NumberOfPoints=\"2\"",
            "NumberOfPoints=\"99999999999999999\"",
        );
        assert!(read_particles(text.as_bytes(), "g.vtu").is_err());
    }
    assert!(t.elapsed().as_secs_f64() < 1.0);
}

#[test]
fn unsupported_features_are_named() {
    let e = read_particles(
        b"<VTKFile type=\"UnstructuredGrid\" compressor=\"vtkLZ4DataCompressor\">",
        "c.vtu",
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("vtkLZ4DataCompressor") && e.contains("not supported"),
        "{e}"
    );
    let e = read_particles(b"<html></html>", "h.vtu")
        .unwrap_err()
        .to_string();
    assert!(e.contains("h.vtu: not a VTK XML file"), "{e}");
    let e = read_particles(b"\xff\xfe\x00garbage<<<", "b.vtu")
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("b.vtu: "), "{e}");
}

/// A string array, and an array only the first piece has, are left out of the particles;
/// asking for either says why.
#[test]
fn arrays_left_out_say_why_when_asked_for() {
    let piece = |arrays: &str| {
        format!(
            "<Piece NumberOfPoints=\"1\" NumberOfCells=\"0\"><Points>\
             <DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">0 0 0</DataArray>\
             </Points><PointData>{arrays}</PointData></Piece>"
        )
    };
    let rho = "<DataArray type=\"Float32\" Name=\"rho\" format=\"ascii\">1000</DataArray>";
    let tag = "<DataArray type=\"String\" Name=\"tag\" format=\"ascii\">97 0</DataArray>";
    let file = format!(
        "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\"><UnstructuredGrid>{}{}\
         </UnstructuredGrid></VTKFile>",
        piece(&format!("{rho}{tag}")),
        piece(tag)
    );
    let p = read_particles(file.as_bytes(), "two.vtu").unwrap();
    assert_eq!(p.len(), 2);
    assert!(p.attributes.is_empty());
    let e = p.require("rho").unwrap_err().to_string();
    assert!(
        e.contains("'rho' is not per-particle data: piece 1 has no 1-component array"),
        "{e}"
    );
    let e = p.require("tag").unwrap_err().to_string();
    assert!(e.contains("its type String is not numeric"), "{e}");
}

#[test]
fn vtp_round_trip_is_exact() {
    let dir = scratch_dir("vtp");
    let path = dir.join("mesh.vtp");
    let mesh = sample_mesh();
    write_file(&path, &mesh).unwrap();
    let back = read_file(&path).unwrap();
    assert_eq!(back, mesh);
    // The same file read as particles: its points and point arrays.
    let p = read_path(&path).unwrap();
    assert_eq!(p.len(), 4);
    assert_eq!(p.require("Normals").unwrap().components, 3);

    let mut plain = mesh.clone();
    plain.normals.clear();
    plain.attributes.clear();
    plain.attributes.push(crate::field::particles::Attribute {
        name: "odd <&> \"name\"".into(),
        components: 2,
        data: vec![1.0; 8],
    });
    write_file(&path, &plain).unwrap();
    assert_eq!(read_file(&path).unwrap(), plain);
    write_file(&path, &Mesh::default()).unwrap();
    assert_eq!(read_file(&path).unwrap(), Mesh::default());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn truncated_vtp_meshes_fail_cleanly() {
    let mut bytes = Vec::new();
    write_mesh(&mut bytes, &sample_mesh()).unwrap();
    assert_eq!(read_mesh(&bytes, "m.vtp").unwrap(), sample_mesh());
    for cut in (1..bytes.len()).step_by(7) {
        let e = read_mesh(&bytes[..cut], "m.vtp").unwrap_err();
        assert!(e.to_string().starts_with("m.vtp: "), "{e}");
    }
}
