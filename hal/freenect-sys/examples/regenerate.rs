//! Writes `src/bindings.rs` from the installed libfreenect.h
//! (`regenerate.sh` runs this).
//!
//! Usage: `cargo run -p freenect-sys --example regenerate [-- OUT]`; the
//! header is `$FREENECT_HEADER` or the first one installed (see generate.rs).

#[path = "../generate.rs"]
mod generate;

use std::path::PathBuf;

fn main() {
    let out = std::env::args_os()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("src/bindings.rs"));
    let result = generate::find_header().and_then(|header| {
        let text = generate::generate(&header)?;
        std::fs::write(&out, text).map_err(|e| format!("{}: cannot write: {e}", out.display()))?;
        Ok(header)
    });
    match result {
        Ok(header) => eprintln!("wrote {} from {}", out.display(), header.display()),
        Err(e) => {
            eprintln!("regenerate: {e}");
            std::process::exit(1);
        }
    }
}
