//! `isobar adaptive` as a user runs it: a real frame in, a closed mesh and its statistics
//! out; bad options refused with a message naming them.

use std::path::PathBuf;
use std::process::Command;

fn isobar() -> Command {
    Command::new(env!("CARGO_BIN_EXE_isobar"))
}

fn temp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("isobar_adaptive_cli_{}_{name}", std::process::id()))
}

fn frame() -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data/splashsurf/double_dam_break_frame_01_4732_particles.vtk")
        .to_string_lossy()
        .into_owned()
}

#[test]
fn adaptive_command_writes_a_closed_surface_and_stats() {
    let (mesh_path, json_path) = (temp("surface.ply"), temp("stats.json"));
    let out = isobar()
        .args([
            "adaptive",
            &frame(),
            "--h",
            "0.05",
            "--iso",
            "0.6",
            "--quiet",
        ])
        .arg("-o")
        .arg(&mesh_path)
        .arg("--stats-json")
        .arg(&json_path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mesh = isobar::io::read_mesh(&mesh_path).unwrap();
    let topo = mesh.topology();
    assert!(topo.is_watertight_oriented(), "{topo:?}");
    let json = std::fs::read_to_string(&json_path).unwrap();
    let triangles: usize = json
        .lines()
        .find_map(|l| l.trim().strip_prefix("\"triangles\": "))
        .and_then(|v| v.trim_end_matches(',').parse().ok())
        .unwrap_or_else(|| panic!("no triangle count in {json}"));
    assert_eq!(triangles, mesh.triangles.len());
    for key in [
        "level_1_triangles",
        "level_3_cells",
        "crack_triangles",
        "time_adaptive_total_s",
    ] {
        assert!(
            json.contains(&format!("\"{key}\"")),
            "{key} missing from {json}"
        );
    }
    let _ = std::fs::remove_file(&mesh_path);
    let _ = std::fs::remove_file(&json_path);
}

/// `isobar adaptive --help` lists only what the adaptive surface takes: none of Marching
/// Correctors' own options, all of the shared SPH ones.
#[test]
fn adaptive_help_lists_only_its_own_options() {
    // The options a command's help lists (descriptions may mention others).
    let options = |command: &str| {
        let out = isobar().args([command, "--help"]).output().unwrap();
        let help = String::from_utf8_lossy(&out.stdout).into_owned();
        let listed: Vec<String> = help
            .lines()
            .filter_map(|l| {
                // "  --name <V>" or "  -o, --name <V>"; description lines start otherwise.
                let mut words = l.split_whitespace();
                match words.next()? {
                    w if w.starts_with("--") => Some(w.to_string()),
                    w if w.starts_with('-') => words.next().map(str::to_string),
                    _ => None,
                }
            })
            .collect();
        (listed, help)
    };
    let (listed, help) = options("adaptive");
    for own in [
        "--preview",
        "--tolerance",
        "--trim",
        "--lattice",
        "--clip",
        "--full-grid",
    ] {
        assert!(!listed.iter().any(|o| o == own), "{own} listed:\n{help}");
    }
    for shared in [
        "--field",
        "--kernel",
        "--h-array",
        "--grid-factor",
        "--backend",
        "--attributes",
        "--output",
    ] {
        assert!(
            listed.iter().any(|o| o == shared),
            "{shared} missing:\n{help}"
        );
    }
    let (listed, help) = options("sph");
    for option in [
        "--preview",
        "--trim",
        "--lattice",
        "--field",
        "--grid-factor",
    ] {
        assert!(
            listed.iter().any(|o| o == option),
            "{option} missing from sph:\n{help}"
        );
    }
}

#[test]
fn adaptive_command_refuses_bad_options() {
    let mesh_path = temp("never.ply");
    for (args, expected) in [
        (vec!["--iso", "0.5,0.6"], "one isovalue"),
        (
            vec!["--iso", "0.6", "--bisection-iterations", "17"],
            "bisection_iterations",
        ),
        // Marching Correctors' own options are refused, not silently ignored.
        (
            vec!["--iso", "0.6", "--preview"],
            "unexpected argument '--preview'",
        ),
        // An array to carry that the particles lack, before any surface is made.
        (
            vec!["--iso", "0.6", "--attributes", "pressure"],
            "no array named 'pressure'",
        ),
        (
            vec!["--iso", "0.6", "--full-grid"],
            "unexpected argument '--full-grid'",
        ),
        (
            vec!["--iso", "0.6", "--trim", "0.1,0.5"],
            "unexpected argument '--trim'",
        ),
        (
            vec!["--iso", "0.6", "--tolerance", "1e-3"],
            "unexpected argument '--tolerance'",
        ),
    ] {
        let out = isobar()
            .args(["adaptive", &frame(), "--h", "0.05", "--quiet"])
            .args(&args)
            .arg("-o")
            .arg(&mesh_path)
            .output()
            .unwrap();
        assert!(!out.status.success(), "{args:?} succeeded");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(expected), "{args:?}: {err}");
        assert!(!mesh_path.exists(), "{args:?} wrote a mesh");
    }
}
