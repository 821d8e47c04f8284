//! The committed C header must be exactly what cbindgen generates from the sources.
//! Regenerate with `ISOBAR_WRITE_HEADER=1 cargo test --release --test header`.

#[test]
fn committed_header_matches_a_fresh_generation() {
    let dir = env!("CARGO_MANIFEST_DIR");
    let config = cbindgen::Config::from_file(format!("{dir}/cbindgen.toml")).unwrap();
    let bindings = cbindgen::Builder::new()
        .with_crate(dir)
        .with_config(config)
        .generate()
        .expect("cbindgen parses the crate");
    let mut fresh = Vec::new();
    bindings.write(&mut fresh);
    let path = format!("{dir}/include/isobar.h");
    if std::env::var_os("ISOBAR_WRITE_HEADER").is_some() {
        std::fs::create_dir_all(format!("{dir}/include")).unwrap();
        std::fs::write(&path, &fresh).unwrap();
    }
    let committed = std::fs::read(&path).unwrap_or_default();
    assert!(
        committed == fresh,
        "include/isobar.h differs from a fresh cbindgen run; regenerate it with ISOBAR_WRITE_HEADER=1 cargo test --release --test header"
    );
}
