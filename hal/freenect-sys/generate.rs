//! The one bindgen configuration of `src/bindings.rs`, shared by
//! `examples/regenerate.rs` (which writes the file) and
//! `tests/bindings_up_to_date.rs` (which checks that the committed file is
//! what it makes from the installed header).

use std::path::{Path, PathBuf};

/// Where libfreenect's header is installed: Debian's `libfreenect-dev` puts
/// it in `/usr/include`, libfreenect's own `make install` in
/// `<prefix>/include/libfreenect/`.
pub const HEADER_CANDIDATES: &[&str] = &[
    "/usr/include/libfreenect/libfreenect.h",
    "/usr/include/libfreenect.h",
    "/usr/local/include/libfreenect/libfreenect.h",
    "/usr/local/include/libfreenect.h",
];

/// The header to generate from: `$FREENECT_HEADER`, else the first of
/// [`HEADER_CANDIDATES`] that exists.
pub fn find_header() -> Result<PathBuf, String> {
    if let Some(path) = std::env::var_os("FREENECT_HEADER") {
        let path = PathBuf::from(path);
        return if path.is_file() {
            Ok(path)
        } else {
            Err(format!("FREENECT_HEADER={}: no such file", path.display()))
        };
    }
    HEADER_CANDIDATES
        .iter()
        .map(PathBuf::from)
        .find(|p| p.is_file())
        .ok_or_else(|| {
            format!(
                "libfreenect.h not found (tried {}); install Debian's libfreenect-dev \
                 (`apt-get install libfreenect-dev`) or set FREENECT_HEADER",
                HEADER_CANDIDATES.join(", ")
            )
        })
}

/// The text of `src/bindings.rs` for `header`.
///
/// Every function of libfreenect.h becomes a field of the `Freenect` struct,
/// resolved when the library is loaded (`Freenect::new(path)`); none is
/// required, so that a library lacking some (libfreenect's fakenect build
/// has a subset) still loads and the caller checks the ones it needs. Enums
/// are modules of constants, so a value the header does not list is no
/// undefined behaviour.
pub fn generate(header: &Path) -> Result<String, String> {
    generate_for(header, None)
}

/// Another target's C ABI, for clang: its triple and the sysroot holding its
/// C library's headers.
pub struct CrossTarget<'a> {
    pub clang_triple: &'a str,
    pub sysroot: &'a Path,
}

/// The text bindgen makes from `header` for the host, or for `cross`: the
/// same configuration, clang told the other target, so that the layout
/// assertions it writes are that target's sizes and alignments.
pub fn generate_for(header: &Path, cross: Option<&CrossTarget<'_>>) -> Result<String, String> {
    let mut builder = bindgen::Builder::default();
    if let Some(cross) = cross {
        builder = builder
            .clang_arg(format!("--target={}", cross.clang_triple))
            .clang_arg(format!("--sysroot={}", cross.sysroot.display()));
    }
    let bindings = builder
        .header(header.to_string_lossy())
        .allowlist_function("freenect_.*")
        .allowlist_type("freenect_.*")
        .allowlist_var("FREENECT_.*")
        .default_enum_style(bindgen::EnumVariation::ModuleConsts)
        .dynamic_library_name("Freenect")
        .dynamic_link_require_all(false)
        .layout_tests(true)
        .derive_default(true)
        .generate_comments(true)
        .formatter(bindgen::Formatter::Prettyplease)
        .generate()
        .map_err(|e| format!("bindgen failed on {}: {e}", header.display()))?;
    Ok(bindings.to_string())
}
