//! Compiles tests/c/capi_test.c against include/isobar.h and the shared library with
//! `gcc -std=c11 -Wall -Wextra -Werror`, then runs it with the CLI's `--backend auto`
//! reason as its argument (the C ABI's note must say the same).

use std::path::PathBuf;
use std::process::Command;

#[test]
fn c_program_extracts_through_the_header_and_library() {
    let crate_dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    // The test binary lives in target/<profile>/deps. `cargo build` (which the test
    // command runs first) puts the cdylib one level up; a cdylib built alongside the
    // tests, when cargo made one, sits beside the test binary and is fresher.
    let exe = std::env::current_exe().unwrap();
    let deps = exe.parent().unwrap().to_path_buf();
    let lib_dir = if deps.join("libisobar.so").exists() {
        deps
    } else {
        deps.parent().unwrap().to_path_buf()
    };
    assert!(
        lib_dir.join("libisobar.so").exists(),
        "no libisobar.so in {}: run `cargo build --release` first",
        lib_dir.display()
    );
    let out = std::env::temp_dir().join(format!("isobar_capi_test_{}", std::process::id()));
    let cc = Command::new("gcc")
        .args(["-std=c11", "-Wall", "-Wextra", "-Werror", "-O1"])
        .arg("-I")
        .arg(crate_dir.join("include"))
        .arg(crate_dir.join("../tests/c/capi_test.c"))
        .arg("-L")
        .arg(&lib_dir)
        .arg(format!("-Wl,-rpath,{}", lib_dir.display()))
        .args(["-lisobar", "-lm", "-o"])
        .arg(&out)
        .output()
        .expect("gcc runs");
    assert!(
        cc.status.success(),
        "gcc failed:\n{}",
        String::from_utf8_lossy(&cc.stderr)
    );
    let run = Command::new(&out).arg(cli_auto_note()).output().unwrap();
    let _ = std::fs::remove_file(&out);
    assert!(
        run.status.success(),
        "capi_test failed:\n{}{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
}

/// What `isobar sph --backend auto` prints on this machine after "backend auto: running on
/// the CPU (" up to the line's closing parenthesis; "" when it prints no such line (AUTO
/// runs on a GPU here).
fn cli_auto_note() -> String {
    let frame = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data/splashsurf/double_dam_break_frame_26_4732_particles.vtk");
    let ply = std::env::temp_dir().join(format!("isobar_capi_auto_{}.ply", std::process::id()));
    let run = Command::new(env!("CARGO_BIN_EXE_isobar"))
        .arg("sph")
        .arg(&frame)
        .args(["--iso", "0.6", "--h", "0.05", "--backend", "auto", "-o"])
        .arg(&ply)
        .output()
        .expect("the isobar CLI runs");
    let _ = std::fs::remove_file(&ply);
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        run.status.success(),
        "isobar sph --backend auto failed:\n{err}"
    );
    const LEAD: &str = "backend auto: running on the CPU (";
    err.lines()
        .find_map(|l| l.strip_prefix(LEAD)?.strip_suffix(')'))
        .unwrap_or_default()
        .to_string()
}
