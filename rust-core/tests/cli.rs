//! The command line as a user runs it.

use std::path::PathBuf;
use std::process::Command;

fn isobar() -> Command {
    Command::new(env!("CARGO_BIN_EXE_isobar"))
}

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("isobar-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn shared(name: &str) -> String {
    format!(
        "{}/../../shared/data/splashsurf/{name}",
        env!("CARGO_MANIFEST_DIR")
    )
}

#[test]
fn demo_output_is_byte_identical_for_one_and_two_threads() {
    let mut files = Vec::new();
    for threads in ["1", "2"] {
        let out = temp(&format!("demo_{threads}.vtp"));
        let status = isobar()
            .args(["demo", "--quiet", "-o"])
            .arg(&out)
            .env("RAYON_NUM_THREADS", threads)
            .output()
            .unwrap();
        assert!(
            status.status.success(),
            "{}",
            String::from_utf8_lossy(&status.stderr)
        );
        let text = String::from_utf8_lossy(&status.stdout);
        assert!(text.contains("written to"), "{text}");
        files.push(std::fs::read(&out).unwrap());
    }
    assert!(files[0].len() > 100_000);
    assert!(
        files[0] == files[1],
        "outputs differ between 1 and 2 threads"
    );
}

#[test]
fn sph_command_writes_a_surface_and_stats() {
    let out = temp("dam.ply");
    let json = temp("dam.json");
    let run = isobar()
        .args([
            "sph",
            &shared("dam_break_frame_9_6859_particles.bgeo"),
            "--iso",
            "0.6",
            "--h",
            "0.05",
            "--grid-factor",
            "0.375",
        ])
        .arg("--stats-json")
        .arg(&json)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let stdout = String::from_utf8_lossy(&run.stdout);
    for row in [
        "seed cells",
        "cache hit ratio",
        "correction max",
        "triangles",
    ] {
        assert!(stdout.contains(row), "stats table lacks '{row}':\n{stdout}");
    }
    let mesh = isobar::io::read_mesh(&out).unwrap();
    assert!(mesh.triangles.len() > 10_000);
    assert!(mesh.topology().is_watertight_oriented());
    let stats = std::fs::read_to_string(&json).unwrap();
    assert!(
        stats.contains(&format!("\"triangles\": {}", mesh.triangles.len())),
        "{stats}"
    );
}

/// `isobar sph --backend gpu` (wgpu; lavapipe in CI) on a real .bgeo frame writes the file
/// `--backend cpu` writes, byte for byte, and its statistics say the GPU ran. Without an
/// adapter this fails, unless ISOBAR_GPU_TESTS=skip (then the error must name the cause).
#[test]
fn sph_backend_gpu_writes_the_cpu_mesh_byte_for_byte() {
    let frame = shared("dam_break_frame_9_6859_particles.bgeo");
    let run = |backend: &str| {
        let out = temp(&format!("backend_{backend}.ply"));
        let json = temp(&format!("backend_{backend}.json"));
        let run = isobar()
            .args(["sph", &frame, "--iso", "0.6", "--h", "0.05", "--quiet"])
            .args(["--backend", backend, "--stats-json"])
            .arg(&json)
            .arg("-o")
            .arg(&out)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&run.stderr).to_string();
        run.status
            .success()
            .then(|| {
                (
                    std::fs::read(&out).unwrap(),
                    std::fs::read_to_string(&json).unwrap(),
                )
            })
            .ok_or(err)
    };
    let (cpu, cpu_stats) = run("cpu").unwrap();
    assert!(cpu_stats.contains("\"backend\": \"cpu\""), "{cpu_stats}");
    let (gpu, gpu_stats) = match run("gpu") {
        Ok(r) => r,
        Err(e) if std::env::var("ISOBAR_GPU_TESTS").as_deref() == Ok("skip") => {
            assert!(e.contains("no GPU adapter"), "{e}");
            return;
        }
        Err(e) => panic!("{e}; install mesa-vulkan-drivers or set ISOBAR_GPU_TESTS=skip"),
    };
    assert!(gpu_stats.contains("\"backend\": \"gpu\""), "{gpu_stats}");
    assert!(cpu.len() > 100_000);
    assert!(cpu == gpu, "--backend gpu wrote another mesh");
}

/// `--backend auto` runs where the core's rule says (a hardware GPU, else the CPU), and
/// says why when that is the CPU; with `--quiet` it says nothing.
#[test]
fn backend_auto_says_why_it_runs_on_the_cpu() {
    let frame = shared("double_dam_break_frame_26_4732_particles.vtk");
    let why = isobar::gpu::auto_fallback_reason();
    for (command, quiet) in [("sph", false), ("adaptive", false), ("sph", true)] {
        let json = temp(&format!("auto_{command}_{quiet}.json"));
        let mut cmd = isobar();
        cmd.args([
            command,
            &frame,
            "--iso",
            "0.6",
            "--h",
            "0.05",
            "--backend",
            "auto",
        ])
        .arg("--stats-json")
        .arg(&json)
        .arg("-o")
        .arg(temp(&format!("auto_{command}.ply")));
        if quiet {
            cmd.arg("--quiet");
        }
        let run = cmd.output().unwrap();
        let err = String::from_utf8_lossy(&run.stderr);
        assert!(run.status.success(), "{err}");
        let stats = std::fs::read_to_string(&json).unwrap();
        let said = err.contains("backend auto: running on the CPU (");
        match &why {
            Some(why) if !quiet => {
                assert!(said && err.contains(why.as_str()), "{command}: {err}");
                assert!(stats.contains("\"backend\": \"cpu\""), "{stats}");
            }
            Some(_) => assert!(!said, "--quiet printed: {err}"),
            None => {
                assert!(!said, "{err}");
                assert!(stats.contains("\"backend\": \"gpu\""), "{stats}");
            }
        }
    }
}

fn fails_with(args: &[&str], expected: &[&str]) {
    let run = isobar().args(args).output().unwrap();
    assert!(!run.status.success(), "{args:?} should fail");
    let err = String::from_utf8_lossy(&run.stderr);
    for e in expected {
        assert!(err.contains(e), "{args:?}: message lacks '{e}':\n{err}");
    }
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn bad_input_gets_a_clear_error_and_no_output() {
    let out = temp("never.ply");
    let o = out.to_str().unwrap();
    fails_with(
        &[
            "sph",
            "/nonexistent/frame.vtk",
            "--iso",
            "1",
            "--h",
            "0.1",
            "-o",
            o,
        ],
        &["/nonexistent/frame.vtk"],
    );
    let frame = shared("double_dam_break_frame_01_4732_particles.vtk");
    fails_with(
        &[
            "sph",
            &frame,
            "--field",
            "temperature",
            "--iso",
            "1",
            "--h",
            "0.05",
            "-o",
            o,
        ],
        &["frame_01_4732_particles.vtk", "temperature"],
    );
    fails_with(&["sph", &frame, "--iso", "0.6", "-o", o], &["--h"]);
    fails_with(
        &[
            "sph",
            &frame,
            "--iso",
            "0.6",
            "--h",
            "0.05",
            "--backend",
            "cuda",
            "-o",
            o,
        ],
        &["backend", "cuda", "cpu, gpu, auto"],
    );
    fails_with(
        &[
            "sph",
            &frame,
            "--iso",
            "0.6",
            "--h",
            "0.05",
            "--full-grid",
            "--backend",
            "gpu",
            "-o",
            o,
        ],
        &["CPU only"],
    );
    fails_with(
        &["sph", &frame, "--iso", "0.6", "--h", "-0.05", "-o", o],
        &["smoothing length"],
    );
    fails_with(
        &[
            "sph",
            &frame,
            "--iso",
            "0.6",
            "--h",
            "0.05",
            "--grid-factor",
            "1e-9",
            "-o",
            o,
        ],
        &["grid factor"],
    );
    let truncated = temp("truncated.vtk");
    let bytes = std::fs::read(&frame).unwrap();
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    fails_with(
        &[
            "sph",
            truncated.to_str().unwrap(),
            "--iso",
            "0.6",
            "--h",
            "0.05",
            "-o",
            o,
        ],
        &["truncated.vtk"],
    );
    let empty = temp("empty.csv");
    std::fs::write(&empty, "x,y,z\n").unwrap();
    fails_with(
        &[
            "sph",
            empty.to_str().unwrap(),
            "--iso",
            "0.6",
            "--h",
            "0.05",
            "-o",
            o,
        ],
        &["empty.csv", "empty"],
    );
    let nan = temp("nan.csv");
    std::fs::write(&nan, "x,y,z\n0,0,0\n0.01,nan,0\n").unwrap();
    fails_with(
        &[
            "sph",
            nan.to_str().unwrap(),
            "--iso",
            "0.6",
            "--h",
            "0.05",
            "-o",
            o,
        ],
        &["nan.csv", "particle 1"],
    );
    assert!(!out.exists(), "a failed run must not leave an output file");
}

/// A path that cannot take the output is refused before any work (it used to end a
/// whole extraction), and a statistics file that cannot be written leaves no mesh.
#[test]
fn output_paths_are_checked_before_the_work() {
    let frame = shared("double_dam_break_frame_01_4732_particles.vtk");
    let run = |output: &str, extra: &[&str], expected: &[&str]| {
        let mut args = vec!["sph", &frame, "--iso", "0.6", "--h", "0.05", "-o", output];
        args.extend_from_slice(extra);
        fails_with(&args, expected);
    };
    // The output is checked first: the missing field would fail only after reading.
    let stl = temp("surface.stl");
    run(
        stl.to_str().unwrap(),
        &["--field", "temperature"],
        &["surface.stl", "cannot write a mesh as '.stl'"],
    );
    // No extension at all: said so (it used to read "cannot write a mesh as '.'").
    let bare = temp("surface");
    run(
        bare.to_str().unwrap(),
        &["--field", "temperature"],
        &["no extension to name the mesh format", ".ply"],
    );
    run(
        "/nonexistent-folder/surface.ply",
        &["--field", "temperature"],
        &["/nonexistent-folder/surface.ply"],
    );
    let out = temp("checked.ply");
    let _ = std::fs::remove_file(&out);
    run(
        out.to_str().unwrap(),
        &["--stats-json", "/nonexistent-folder/stats.json"],
        &["/nonexistent-folder/stats.json"],
    );
    assert!(
        !out.exists(),
        "no mesh written when its statistics cannot be"
    );
    let fe = format!("{}/data/fe/mfem_poisson_q3.vtu", env!("CARGO_MANIFEST_DIR"));
    fails_with(
        &[
            "fe",
            &fe,
            "--field",
            "nope",
            "--iso",
            "0.03",
            "-o",
            out.to_str().unwrap(),
        ],
        &["point samples", ".ply"],
    );
}

/// A sequence of one frame still fills the '#' run with the frame's number.
#[test]
fn a_one_frame_sequence_fills_the_pattern() {
    let dir = temp("one-frame");
    std::fs::create_dir_all(&dir).unwrap();
    let input = dir.join("frame_0007.csv");
    let mut text = String::from("x,y,z\n");
    for i in 0..27 {
        let at = |k: usize| 0.05 * (i / k % 3) as f64;
        text += &format!("{},{},{}\n", at(1), at(3), at(9));
    }
    std::fs::write(&input, text).unwrap();
    let pattern = dir.join("surface_####.ply");
    let run = isobar()
        .args([
            "sph",
            input.to_str().unwrap(),
            "--iso",
            "0.5",
            "--h",
            "0.05",
            "--quiet",
        ])
        .arg("-o")
        .arg(&pattern)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(dir.join("surface_0007.ply").exists());
    assert!(!pattern.exists(), "the pattern itself is not a file name");
    // An isovalue above the field: an empty mesh is written, and the user told.
    let run = isobar()
        .args([
            "sph",
            input.to_str().unwrap(),
            "--iso",
            "1000",
            "--h",
            "0.05",
            "--quiet",
        ])
        .arg("-o")
        .arg(dir.join("empty.ply"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{err}");
    assert!(
        err.contains("frame_0007.csv") && err.contains("no surface at isovalue 1000"),
        "{err}"
    );
    // Frames 7, 8 and 10: the missing 9 is named, and the others still run.
    for n in [8, 10] {
        std::fs::copy(&input, dir.join(format!("frame_{n:04}.csv"))).unwrap();
    }
    let run = isobar()
        .args(["sph", dir.join("frame_####.csv").to_str().unwrap()])
        .args(["--iso", "0.5", "--h", "0.05", "--quiet", "-o"])
        .arg(&pattern)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{err}");
    assert!(err.contains("frame 9 missing"), "{err}");
    assert!(dir.join("surface_0010.ply").exists());
    // One file of the set with a plain output: that file alone (it used to be refused:
    // "3 frames match"), no sequence scanned.
    let one = dir.join("one.ply");
    let run = isobar()
        .args(["sph", input.to_str().unwrap()])
        .args(["--iso", "0.5", "--h", "0.05", "--quiet", "-o"])
        .arg(&one)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success() && one.exists(), "{err}");
    assert!(!err.contains("missing"), "{err}");
    // The whole set into one mesh, or its statistics into one file: each frame would
    // overwrite the last, so both are refused before any frame is read.
    let (set, all) = (dir.join("frame_####.csv"), dir.join("all.ply"));
    let common = ["--iso", "0.5", "--h", "0.05", "--quiet", "-o"];
    let mut args = vec!["sph", set.to_str().unwrap()];
    args.extend(common);
    args.push(all.to_str().unwrap());
    fails_with(&args, &["3 frames match", "'#'"]);
    let stats = dir.join("stats.json");
    let mut args = vec!["sph", input.to_str().unwrap()];
    args.extend(common);
    args.extend([
        pattern.to_str().unwrap(),
        "--stats-json",
        stats.to_str().unwrap(),
    ]);
    fails_with(&args, &["stats-json", "3 frames match"]);
    assert!(!all.exists() && !stats.exists());
}

#[test]
fn comma_separated_options_parse_as_documented() {
    let out = temp("options.ply");
    let frame = shared("double_dam_break_frame_26_4732_particles.vtk");
    let run = isobar()
        .args([
            "sph",
            &frame,
            "--field",
            "SumOfWeights",
            "--iso",
            "0.5,0.6",
            "--h",
            "0.05",
        ])
        .args([
            "--trim",
            "0.1,0.3",
            "--lattice",
            "0,0,0,0.02",
            "--clip",
            "-9,-9,-9,0.5,9,9",
        ])
        .args(["--quiet", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    fails_with(
        &[
            "sph",
            &frame,
            "--iso",
            "0.6",
            "--h",
            "0.05",
            "--lattice",
            "0,0,0",
            "-o",
            out.to_str().unwrap(),
        ],
        &["lattice", "4"],
    );
}

/// h in other units than the positions (millimetres against metres) makes every
/// particle a neighbour of every other: said on stderr, while a fitting h says nothing.
#[test]
fn a_kernel_wider_than_the_data_is_reported() {
    let frame = shared("double_dam_break_frame_26_4732_particles.vtk");
    for (h, warned) in [("0.05", false), ("50", true)] {
        let out = temp(&format!("wide_{h}.ply"));
        let run = isobar()
            .args(["sph", &frame, "--field", "SumOfWeights", "--iso", "0.5"])
            .args(["--h", h, "--quiet", "-o"])
            .arg(&out)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&run.stderr);
        assert!(run.status.success(), "{err}");
        assert_eq!(
            err.contains("wider than the particles' extent"),
            warned,
            "h {h}: {err}"
        );
    }
}
