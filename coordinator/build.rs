//! With the `denoise` feature, the binary finds Open Image Denoise where it was built against
//! (`OIDN_DIR/lib`, set by .cargo/config.toml), with no LD_LIBRARY_PATH: the `oidn` crate links
//! the library but sets no run path.
fn main() {
    println!("cargo:rerun-if-env-changed=OIDN_DIR");
    if std::env::var_os("CARGO_FEATURE_DENOISE").is_some()
        && let Some(dir) = std::env::var_os("OIDN_DIR")
    {
        let lib = std::path::Path::new(&dir).join("lib");
        println!("cargo:rustc-link-arg=-Wl,-rpath,{}", lib.display());
    }
}
