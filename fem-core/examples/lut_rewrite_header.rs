//! Rewrite a table file's header from its curves, the curves byte for byte unchanged:
//! `cargo run -p fem-core --release --example lut_rewrite_header -- FILE...`. For figures
//! the header derives from the curves (the interpolation errors) after a new one is
//! recorded; the file's content hash changes with its header, so a model file naming the
//! old hash asks for a new diagnosis.

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let paths: Vec<String> = std::env::args().skip(1).collect();
    if paths.is_empty() {
        return Err("usage: lut_rewrite_header FILE...".into());
    }
    for path in paths {
        let path = std::path::Path::new(&path);
        let before = fem_core::lut::read_lut(path)?;
        let sha256 = fem_core::lut::write_lut(path, &before.lut)?;
        let after = fem_core::lut::read_lut(path)?;
        if after.lut.curves != before.lut.curves {
            return Err(format!("{}: the curves changed on rewriting", path.display()).into());
        }
        println!(
            "{}: sha256 {} -> {sha256}, {} bytes",
            path.display(),
            before.sha256,
            after.size_bytes
        );
    }
    Ok(())
}
