//! `isobar slide-build` and `isobar slide` as a user runs them.

use isobar::io::{read_volume, RawLayout, RawType};
use isobar::progress::Progress;
use isobar::slider::{full, Store};
use std::io::Write;
use std::path::PathBuf;
use std::process::{Command, Stdio};

fn isobar() -> Command {
    Command::new(env!("CARGO_BIN_EXE_isobar"))
}

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("isobar-slider-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// Runs `isobar slide STORE` with `input` on stdin.
fn slide(store: &std::path::Path, input: &[u8]) -> std::process::Output {
    slide_with(store, &[], input)
}

/// The `n` output lines of a successful `isobar slide STORE ARGS` with `input` on stdin.
fn slide_lines(store: &std::path::Path, args: &[&str], input: &str, n: usize) -> Vec<String> {
    let out = slide_with(store, args, input.as_bytes());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let lines: Vec<String> = text.lines().map(str::to_string).collect();
    assert_eq!(lines.len(), n, "{text}");
    lines
}

/// Runs `isobar slide STORE ARGS` with `input` on stdin.
fn slide_with(store: &std::path::Path, args: &[&str], input: &[u8]) -> std::process::Output {
    let mut child = isobar()
        .arg("slide")
        .arg(store)
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // A command that refuses its arguments exits before reading: the pipe may then be
    // closed under the write, which is not the test's failure (its output says).
    let _ = child.stdin.take().unwrap().write_all(input);
    child.wait_with_output().unwrap()
}

#[test]
fn build_then_slide_from_stdin_matches_marching_cubes() {
    // A u16 raw volume: a ring-shaped bump with a ramp.
    let dims = [18usize, 15, 13];
    let mut bytes = Vec::new();
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                let (fx, fy, fz) = (x as f64 - 8.5, y as f64 - 7.0, z as f64 - 6.0);
                let ring = ((fx * fx + fy * fy).sqrt() - 4.5).powi(2) + fz * fz;
                let v = 3000.0 * (-ring / 6.0).exp() + 20.0 * x as f64;
                bytes.extend_from_slice(&(v as u16).to_le_bytes());
            }
        }
    }
    let raw = temp("ring.raw");
    std::fs::write(&raw, &bytes).unwrap();
    let store = temp("ring.isoslider");
    let out = isobar()
        .args([
            "slide-build",
            "--quiet",
            "--raw-type",
            "u16",
            "--raw-dims",
            "18,15,13",
        ])
        .arg(&raw)
        .arg("-o")
        .arg(&store)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("18×15×13 u16 volume"), "{text}");

    let isos = [1500.0, 1510.0, 800.0, 2900.0, 1500.0, 100.0];
    let input: String = isos.iter().map(|v| format!("{v}\n")).collect();
    let lines = slide_lines(&store, &[], &input, isos.len());
    let layout = RawLayout {
        dims,
        ty: RawType::U16,
        big_endian: false,
        origin: glam::DVec3::ZERO,
        spacing: glam::DVec3::ONE,
    };
    let volume = read_volume(&raw, None, Some(layout)).unwrap();
    for (line, iso) in lines.iter().zip(isos) {
        let mesh = full::extract(&volume, iso, &mut Progress::none()).unwrap();
        assert!(!mesh.triangles.is_empty());
        let want = format!(
            "iso {iso} triangles {} vertices {} ",
            mesh.triangles.len(),
            mesh.positions.len()
        );
        assert!(line.starts_with(&want), "{line} vs {want}");
        assert!(line.contains("update_ms"), "{line}");
        assert!(line.contains("held_mib"), "{line}");
        assert!(!line.contains("lod_"), "{line}");
    }

    // --lod: bound 0 is the exact mesh; a loose bound merges cells into fewer triangles.
    let field = |line: &str, name: &str| -> usize {
        let mut words = line.split_whitespace();
        words
            .find(|w| *w == name)
            .unwrap_or_else(|| panic!("{name}: {line}"));
        words.next().unwrap().parse().unwrap()
    };
    for (bound, exact) in [("0", true), ("0.05", false)] {
        let lines = slide_lines(&store, &["--lod", bound], &input, isos.len());
        let (mut all, mut lod) = (0, 0);
        for line in &lines {
            let (t, l) = (field(line, "triangles"), field(line, "lod_triangles"));
            assert!(line.contains("lod_ms"), "{line}");
            if exact {
                assert_eq!(l, t, "{line}");
                assert_eq!(
                    field(line, "lod_vertices"),
                    field(line, "vertices"),
                    "{line}"
                );
            }
            (all, lod) = (all + t, lod + l);
        }
        if !exact {
            assert!(lod < all, "--lod {bound}: {lod} of {all} triangles");
        }
    }
    let out = slide_with(&store, &["--lod", "-1"], b"1500\n");
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("lod error bound"));
}

#[test]
fn bad_inputs_fail_with_a_clear_message() {
    let junk = temp("junk.isoslider");
    std::fs::write(&junk, b"hello").unwrap();
    let out = isobar().arg("slide").arg(&junk).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("junk.isoslider") && err.contains("magic"),
        "{err}"
    );

    let raw = temp("short.raw");
    std::fs::write(&raw, [0u8; 10]).unwrap();
    let out = isobar()
        .args(["slide-build", "--quiet", "--raw-dims", "2,2,3"])
        .arg(&raw)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("short.raw") && err.contains("needs 12 bytes"),
        "{err}"
    );

    let good = temp("one.raw");
    std::fs::write(&good, [0u8, 1, 2, 3, 4, 5, 6, 7]).unwrap();
    let store = temp("one.isoslider");
    assert!(isobar()
        .args(["slide-build", "--quiet", "--raw-dims", "2,2,2"])
        .arg(&good)
        .output()
        .unwrap()
        .status
        .success());
    let out = slide(&store, b"3.5\nabc\n");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("line 2") && err.contains("'abc'"), "{err}");
    // A step or starting isovalue no key press could use is refused before the store
    // is opened.
    for (args, name) in [
        (["--step", "NaN"], "'step'"),
        (["--step", "1e300"], "'step'"),
        (["--step", "0"], "'step'"),
        (["--iso", "inf"], "'iso'"),
    ] {
        let out = slide_with(&store, &args, b"3.5\n");
        assert!(!out.status.success(), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(name), "{args:?}: {err}");
    }
}

/// u16 little-endian bytes of an 18×15×13 ring-shaped bump on a ramp, moved `shift` nodes
/// along x.
fn ring_volume(shift: f64) -> Vec<u8> {
    let mut bytes = Vec::new();
    for z in 0..13 {
        for y in 0..15 {
            for x in 0..18 {
                let (fx, fy, fz) = (x as f64 - 8.5 - shift, y as f64 - 7.0, z as f64 - 6.0);
                let ring = ((fx * fx + fy * fy).sqrt() - 4.5).powi(2) + fz * fz;
                let v = 3000.0 * (-ring / 6.0).exp() + 20.0 * x as f64;
                bytes.extend_from_slice(&(v as u16).to_le_bytes());
            }
        }
    }
    bytes
}

#[test]
fn slide_on_a_volume_builds_its_store_once_and_rebuilds_a_stale_one() {
    let raw = temp("volume-ring.raw");
    let store = temp("volume-ring.isoslider");
    let raw_args = ["--raw-type", "u16", "--raw-dims", "18,15,13"];
    let layout = RawLayout {
        dims: [18, 15, 13],
        ty: RawType::U16,
        big_endian: false,
        origin: glam::DVec3::ZERO,
        spacing: glam::DVec3::ONE,
    };
    let isos = [1500.0, 1510.0, 800.0, 2900.0];
    let input: String = isos.iter().map(|v| format!("{v}\n")).collect();
    // `slide VOLUME`: stderr says whether the store was built or reused; each line's
    // counts are a from-scratch marching-cubes mesh of the volume as it is now.
    let run = |want: &str| {
        let out = slide_with(&raw, &raw_args, input.as_bytes());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{err}");
        assert!(err.contains(want), "{err}");
        let volume = read_volume(&raw, None, Some(layout)).unwrap();
        let text = String::from_utf8_lossy(&out.stdout);
        assert_eq!(text.lines().count(), isos.len(), "{text}");
        for (line, iso) in text.lines().zip(isos) {
            let mesh = full::extract(&volume, iso, &mut Progress::none()).unwrap();
            let want = format!(
                "iso {iso} triangles {} vertices {} ",
                mesh.triangles.len(),
                mesh.positions.len()
            );
            assert!(line.starts_with(&want), "{line} vs {want}");
        }
    };
    let _ = std::fs::remove_file(&store);
    std::fs::write(&raw, ring_volume(0.0)).unwrap();
    run("building its store");
    assert!(Store::open(&store).is_ok(), "the store beside the volume");
    let built = std::fs::metadata(&store).unwrap().modified().unwrap();
    run("using its store");
    assert_eq!(
        std::fs::metadata(&store).unwrap().modified().unwrap(),
        built,
        "a store holding the volume is not rewritten"
    );
    // The volume changed (same size, same lattice): the old store no longer holds it.
    std::fs::write(&raw, ring_volume(2.0)).unwrap();
    run("building its store");

    // --store elsewhere; a file there that is not a store is left alone.
    let other = temp("volume-ring-notes.isoslider");
    std::fs::write(&other, b"my notes").unwrap();
    let mut args = raw_args.to_vec();
    args.extend(["--store", other.to_str().unwrap()]);
    let out = slide_with(&raw, &args, b"1500\n");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("volume-ring-notes.isoslider") && err.contains("not a slider store"),
        "{err}"
    );
    assert_eq!(std::fs::read(&other).unwrap(), b"my notes");
    // Volume options on a store are refused, not ignored.
    let out = slide_with(&store, &raw_args, b"1500\n");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("is a slider store already"), "{err}");
}

/// Ctrl-C or SIGTERM during `slide-build` stops it the way a cancel does: no temporary
/// store and no spool is left beside the output, an earlier store is kept, and the exit
/// status is 130. (The process used to die where it stood, leaving its hidden temporary.)
#[test]
fn an_interrupted_build_leaves_no_temporary_files() {
    let dir = temp("interrupted");
    std::fs::create_dir_all(&dir).unwrap();
    let n = 160usize;
    let mut bytes = Vec::with_capacity(n * n * n * 4);
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let d = [x, y, z].map(|c| c as f32 - n as f32 / 2.0);
                let v = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() + (x as f32 * 0.3).sin();
                bytes.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    let raw = dir.join("v.raw");
    std::fs::write(&raw, &bytes).unwrap();
    let store = dir.join("v.isoslider");
    let hidden = || {
        std::fs::read_dir(&dir)
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().starts_with('.'))
            .map(|e| (e.file_name(), e.metadata().map_or(0, |m| m.len())))
            .collect::<Vec<_>>()
    };
    // Sorted on disk (a budget far below 29 bytes a node): the slow path, spools open.
    let build = |signal: libc::c_int, wait_for_temporary: bool| {
        let mut child = isobar()
            .args(["slide-build", raw.to_str().unwrap(), "-o"])
            .arg(&store)
            .args(["--raw-type", "f32", "--raw-dims", "160,160,160"])
            .args(["--memory-budget", "40000000", "--quiet"])
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let start = std::time::Instant::now();
        if wait_for_temporary {
            // Until the store's temporary holds data: the signal comes while it is written.
            while !hidden().iter().any(|(_, len)| *len > 0)
                && start.elapsed().as_secs() < 60
                && child.try_wait().unwrap().is_none()
            {
                std::thread::sleep(std::time::Duration::from_micros(200));
            }
        } else {
            std::thread::sleep(std::time::Duration::from_millis(300));
        }
        unsafe { libc::kill(child.id() as libc::pid_t, signal) };
        child.wait_with_output().unwrap()
    };

    let run = build(libc::SIGINT, false);
    let err = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(130), "{err}");
    assert!(err.contains("interrupted"), "{err}");
    assert!(!store.exists());
    assert_eq!(hidden(), vec![]);

    // A store already there stays as it was.
    std::fs::write(&store, b"an earlier store").unwrap();
    let run = build(libc::SIGTERM, false);
    assert_eq!(run.status.code(), Some(130));
    assert_eq!(std::fs::read(&store).unwrap(), b"an earlier store");
    assert_eq!(hidden(), vec![]);
    std::fs::remove_file(&store).unwrap();

    // During the store's write the file is finished and renamed first (nothing half
    // written is left), and the command either ends there or was stopped before it.
    let run = build(libc::SIGTERM, true);
    assert_eq!(hidden(), vec![], "{}", String::from_utf8_lossy(&run.stderr));
    match run.status.code() {
        Some(0) => {
            Store::open(&store).unwrap();
        }
        Some(130) => assert!(!store.exists()),
        other => panic!("{other:?}: {}", String::from_utf8_lossy(&run.stderr)),
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// With isovalues on a pipe that stays open, Ctrl-C ends `slide` while it waits for the
/// next line (std's line reader retried after the signal and waited on), with status 130.
#[test]
fn an_interrupt_ends_slide_while_it_waits_for_isovalues() {
    use std::io::BufRead;
    let raw = temp("waiting-ring.raw");
    std::fs::write(&raw, ring_volume(0.0)).unwrap();
    let mut child = isobar()
        .arg("slide")
        .arg(&raw)
        .args(["--raw-type", "u16", "--raw-dims", "18,15,13"])
        .arg("--store")
        .arg(temp("waiting-ring.isoslider"))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    writeln!(stdin, "1500").unwrap();
    let mut first = String::new();
    std::io::BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    assert!(first.starts_with("iso 1500 "), "{first}");
    // The first line is answered: `slide` now waits on the open pipe.
    unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) };
    let start = std::time::Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        assert!(
            start.elapsed().as_secs() < 20,
            "slide did not end on SIGINT"
        );
        std::thread::sleep(std::time::Duration::from_millis(10));
    };
    drop(stdin);
    assert_eq!(status.code(), Some(130));
}

#[test]
fn an_isovalue_outside_the_values_is_named_on_stderr() {
    // The values span 0..3000+; 1e9 and -5 have no surface, which the user is told (the
    // line of the input and the range), while stdout keeps one parseable line per value.
    let raw = temp("outside-ring.raw");
    std::fs::write(&raw, ring_volume(0.0)).unwrap();
    let out = slide_with(
        &raw,
        &["--raw-type", "u16", "--raw-dims", "18,15,13"],
        b"1500\n1e9\n-5\n",
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    let text = String::from_utf8_lossy(&out.stdout);
    let counts: Vec<&str> = text.lines().map(|l| l.split(' ').nth(3).unwrap()).collect();
    assert!(counts[0] != "0" && counts[1..] == ["0", "0"], "{text}");
    let warned: Vec<&str> = err.lines().filter(|l| l.contains("warning")).collect();
    assert_eq!(warned.len(), 2, "{err}");
    assert!(
        warned[0].starts_with("isobar: warning: line 2: no surface at isovalue 1000000000: the values range over 0 .."),
        "{err}"
    );
    assert!(
        warned[1].starts_with("isobar: warning: line 3: no surface at isovalue -5"),
        "{err}"
    );
}
