//! Depth image files (`depth_image`): fakenect dumps, 16-bit PGM, PNG and TIFF.
//!
//! The PNG and TIFF readers run the `png` and `tiff` crates inside
//! `catch_unwind` (groundcal's `guard_panics`) and turn a decoder panic into an
//! error. libfuzzer-sys's panic hook would abort on such a panic even though
//! groundcal handles it, so this target installs its own hook: a panic that
//! escapes a groundcal function is a crash; one caught by `guard_panics` is
//! logged once per place (a bug in the decoder, not in groundcal), and is a
//! crash too when `GROUNDCAL_FUZZ_STRICT_DECODERS` is set.
#![no_main]

use std::cell::{Cell, RefCell};
use std::collections::HashSet;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use std::sync::Mutex;

use groundcal::formats::depth_image::{
    encode_fakenect_pgm, parse_fakenect_pgm, parse_png16, parse_standard_pgm16, parse_tiff16,
    DepthImage, DepthImageError,
};
use groundcal_fuzz::{path, PATH};
use libfuzzer_sys::fuzz_target;

/// Larger inputs are not tried (the readers accept files up to 64 MiB; the
/// size checks themselves are exercised by the headers, not by length).
const MAX_INPUT: usize = 1 << 20;

type Parser = fn(&Path, &[u8]) -> Result<DepthImage, DepthImageError>;

thread_local! {
    /// Whether a parser is running (its panics are recorded, not reported).
    static IN_PARSER: Cell<bool> = const { Cell::new(false) };
    /// The last panic's message and place inside a parser, set by the hook.
    static LAST_PANIC: RefCell<Option<String>> = const { RefCell::new(None) };
}

/// Places of decoder panics already logged.
static LOGGED: Mutex<Option<HashSet<String>>> = Mutex::new(None);

fn call(name: &str, parse: Parser, data: &[u8]) -> Option<DepthImage> {
    LAST_PANIC.with(|p| p.borrow_mut().take());
    IN_PARSER.with(|f| f.set(true));
    let result = catch_unwind(AssertUnwindSafe(|| parse(path(), data)));
    IN_PARSER.with(|f| f.set(false));
    let result = match result {
        Ok(result) => result,
        Err(_) => {
            let panic = LAST_PANIC
                .with(|p| p.borrow_mut().take())
                .unwrap_or_default();
            eprintln!("{name} panicked: {panic}");
            std::process::abort();
        }
    };
    match result {
        Ok(image) => Some(image),
        Err(e) => {
            let message = e.to_string();
            assert!(
                message.starts_with(PATH),
                "{name}: error without the path: {message}"
            );
            if let Some(panic) = LAST_PANIC.with(|p| p.borrow_mut().take()) {
                // Caught inside the parser: only guard_panics does that.
                assert!(
                    matches!(e, DepthImageError::Decode { .. }) && message.contains("panicked"),
                    "{name}: a panic was caught but the error does not say so: {message}"
                );
                if std::env::var_os("GROUNDCAL_FUZZ_STRICT_DECODERS").is_some() {
                    eprintln!("{name}: decoder panicked (caught by guard_panics): {panic}");
                    std::process::abort();
                }
                let place = panic.split(':').take(2).collect::<Vec<_>>().join(":");
                let mut logged = LOGGED.lock().unwrap();
                if logged.get_or_insert_with(HashSet::new).insert(place) {
                    eprintln!("NOTE {name}: decoder panicked (caught by guard_panics): {panic}");
                }
            }
            None
        }
    }
}

fn check_image(name: &str, image: &DepthImage) {
    assert!(
        (1..=4096).contains(&image.width) && (1..=4096).contains(&image.height),
        "{name}: {}x{} accepted",
        image.width,
        image.height
    );
    assert_eq!(
        image.pixels.len(),
        image.width * image.height,
        "{name}: {}x{} image with {} pixels",
        image.width,
        image.height,
        image.pixels.len()
    );
}

fuzz_target!(
    init: {
        // Outside a parser, libfuzzer-sys's hook (print, then abort).
        let fuzzer_hook = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !IN_PARSER.with(|f| f.get()) {
                return fuzzer_hook(info);
            }
            let place = info
                .location()
                .map(|l| format!("{}:{}", l.file(), l.line()))
                .unwrap_or_default();
            let message = info
                .payload()
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| info.payload().downcast_ref::<String>().cloned())
                .unwrap_or_default();
            LAST_PANIC.with(|p| *p.borrow_mut() = Some(format!("{place}: {message}")));
        }));
    },
    |data: &[u8]| {
        if data.len() > MAX_INPUT {
            return;
        }
        // Each reader sees every input (they refuse other formats at once).
        if let Some(image) = call("parse_fakenect_pgm", parse_fakenect_pgm, data) {
            check_image("parse_fakenect_pgm", &image);
            // Pixel data is exactly two bytes per pixel after the header.
            assert!(data.len() > 2 * image.pixels.len());
            assert_eq!(
                &data[data.len() - 2 * image.pixels.len()..][..2],
                &image.pixels[0].to_le_bytes()
            );
            // What the writer makes of it reads back the same.
            let written = encode_fakenect_pgm(&image);
            assert_eq!(parse_fakenect_pgm(path(), &written).unwrap(), image);
        }
        if let Some(image) = call("parse_standard_pgm16", parse_standard_pgm16, data) {
            check_image("parse_standard_pgm16", &image);
            assert!(data.len() > 2 * image.pixels.len());
            assert_eq!(
                &data[data.len() - 2 * image.pixels.len()..][..2],
                &image.pixels[0].to_be_bytes()
            );
        }
        if let Some(image) = call("parse_png16", parse_png16, data) {
            check_image("parse_png16", &image);
        }
        if let Some(image) = call("parse_tiff16", parse_tiff16, data) {
            check_image("parse_tiff16", &image);
        }
    }
);
