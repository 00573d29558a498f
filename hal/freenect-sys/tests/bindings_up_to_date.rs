//! The committed `src/bindings.rs` is what bindgen makes from the installed
//! libfreenect.h with `generate.rs`'s configuration (`regenerate.sh` writes
//! it). bindgen loads libclang at run time.
//!
//! Needs Debian's `libfreenect-dev` (the header) and `libclang-dev`
//! (libclang). Without them the test fails under `CI=true` and warns and
//! passes otherwise.

#[path = "../generate.rs"]
mod generate;

use std::io::Write;
use std::path::Path;

/// Fails under `CI=true`; otherwise a loud warning (written to the stream
/// itself: the harness swallows what a passing test prints).
fn missing(message: &str) {
    if std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!("{message}");
    }
    let bar = "!".repeat(78);
    let _ = writeln!(
        std::io::stderr(),
        "\n{bar}\nWARNING: freenect-sys bindings check NOT RUN: {message}\n{bar}\n"
    );
}

#[test]
fn committed_bindings_are_what_bindgen_makes_from_the_installed_header() {
    let header = match generate::find_header() {
        Ok(h) => h,
        Err(e) => return missing(&e),
    };
    if !bindgen_has_libclang() {
        return missing(
            "libclang is not installed: bindgen needs it at run time; install Debian's \
             libclang-dev (`apt-get install libclang-dev`)",
        );
    }
    let fresh = generate::generate(&header).unwrap_or_else(|e| panic!("{e}"));
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/bindings.rs");
    let committed = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("{}: cannot read: {e}", path.display()));
    if committed != fresh {
        let line = committed
            .lines()
            .zip(fresh.lines())
            .position(|(a, b)| a != b)
            .map(|i| i + 1)
            .unwrap_or_else(|| committed.lines().count().min(fresh.lines().count()) + 1);
        panic!(
            "{} differs from what bindgen makes from {} (first at line {line}); \
             run hal/freenect-sys/regenerate.sh and commit the result",
            path.display(),
            header.display()
        );
    }
}

/// The robot's upper computer is usually arm64: the bindings that bindgen
/// makes for aarch64 (clang told the target, with Debian's cross C library
/// headers) are the committed ones, character for character, layout
/// assertions included. So the structs' sizes, alignments and field offsets
/// are the same there, and one file serves both (the assertions are also
/// checked at compile time, on every build for either target).
///
/// Needs `libc6-dev-arm64-cross` (the headers in `/usr/aarch64-linux-gnu`).
#[test]
fn committed_bindings_hold_for_aarch64() {
    let header = match generate::find_header() {
        Ok(h) => h,
        Err(e) => return missing(&e),
    };
    let sysroot = Path::new("/usr/aarch64-linux-gnu");
    if !sysroot.join("include/stdint.h").is_file() {
        return missing(
            "the aarch64 C library's headers are not installed; install Debian's \
             libc6-dev-arm64-cross (`apt-get install libc6-dev-arm64-cross`)",
        );
    }
    if !bindgen_has_libclang() {
        return missing("libclang is not installed (Debian's libclang-dev)");
    }
    let cross = generate::CrossTarget {
        clang_triple: "aarch64-linux-gnu",
        sysroot,
    };
    let fresh = generate::generate_for(&header, Some(&cross)).unwrap_or_else(|e| panic!("{e}"));
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/bindings.rs");
    let committed = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("{}: cannot read: {e}", path.display()));
    if let Some((line, (ours, theirs))) = committed
        .lines()
        .zip(fresh.lines())
        .enumerate()
        .find(|(_, (a, b))| a != b)
    {
        panic!(
            "{} differs from bindgen's for aarch64 at line {}:\n  committed: {ours}\n  aarch64:   {theirs}",
            path.display(),
            line + 1
        );
    }
    assert_eq!(
        committed.lines().count(),
        fresh.lines().count(),
        "line counts differ"
    );
}

/// Whether bindgen can load a libclang (without it, `generate` panics).
fn bindgen_has_libclang() -> bool {
    std::panic::catch_unwind(|| {
        bindgen::Builder::default()
            .header_contents("probe.h", "int probe(void);")
            .generate()
            .is_ok()
    })
    .unwrap_or(false)
}
