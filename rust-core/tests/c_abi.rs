//! Compiles tests/c/capi_test.c against include/isobar.h and the shared library with
//! `gcc -std=c11 -Wall -Wextra -Werror`, then runs it.

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
    let run = Command::new(&out).output().unwrap();
    let _ = std::fs::remove_file(&out);
    assert!(
        run.status.success(),
        "capi_test failed:\n{}{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
}
