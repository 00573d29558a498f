//! Raw bindings to libfreenect (`libfreenect.h`, libfreenect 0.5), for the
//! Kinect v1.
//!
//! `bindings.rs` is bindgen's output, committed; `regenerate.sh` makes it
//! again from the installed header and `tests/bindings_up_to_date.rs` checks
//! that it is what bindgen makes (see `generate.rs` for the configuration).
//!
//! The library is loaded at run time: [`Freenect::new`] takes the path of a
//! `libfreenect.so` (or the fakenect build that plays a dump back), and every
//! function of the header is a field holding either the resolved symbol or
//! the error of resolving it. Nothing links against libfreenect, so a program
//! using this crate builds and runs where libfreenect is not installed.
//!
//! Everything here is `unsafe` and raw; `groundcal_hal::kinect` is the safe
//! wrapper.

#![allow(
    non_upper_case_globals,
    non_camel_case_types,
    non_snake_case,
    dead_code,
    clippy::all,
    clippy::pedantic,
    // The generated calls `expect` their symbol: groundcal-hal calls none
    // before it has checked that every symbol it uses was found.
    clippy::unwrap_used,
    clippy::expect_used,
    rustdoc::all
)]

// bindgen's output, kept out of rustfmt's way (it is formatted by
// prettyplease, and must stay byte-identical to what bindgen makes).
include!("bindings.rs");

/// The sonames under which libfreenect 0.5 is usually installed, most
/// specific first (Debian's `libfreenect0.5` ships `libfreenect.so.0.5`;
/// `libfreenect.so` comes with `libfreenect-dev`).
pub const DEFAULT_SONAMES: &[&str] = &["libfreenect.so.0.5", "libfreenect.so"];

/// The loader the bindings use, for callers that inspect its errors.
pub use libloading;
