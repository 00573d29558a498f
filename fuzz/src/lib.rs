//! Helpers shared by the fuzz targets in `fuzz_targets/`.

use std::borrow::Cow;
use std::path::Path;

use groundcal::formats::recording::InputError;

/// The path every target passes to the parsers (they only use it in messages).
pub const PATH: &str = "fuzz-input";

/// The path as a `Path`.
pub fn path() -> &'static Path {
    Path::new(PATH)
}

/// The texts a text parser is called with: the bytes as UTF-8 when they are
/// (what the readers pass on), else the lossy conversion (U+FFFD for each bad
/// sequence), so that every input reaches the parser as some text.
pub fn text_of(data: &[u8]) -> Cow<'_, str> {
    String::from_utf8_lossy(data)
}

/// Checks what every `InputError` must satisfy: it names the path it was
/// given, its line (if any) lies within the text, and it has a message.
pub fn check_input_error(e: &InputError, text: &str) {
    assert_eq!(e.path, path(), "error names another path: {e}");
    if let Some(line) = e.line {
        // serde_json reports an error at the end of a text ending in a newline
        // on the line after the last; nothing may be further than that.
        let last = text.bytes().filter(|&b| b == b'\n').count() + 1;
        assert!(
            (1..=last).contains(&line),
            "error on line {line} of a text of {last} lines: {e}"
        );
    }
    assert!(
        !e.message.is_empty() || tolerate_known_bugs(),
        "error without a message: {e:?}"
    );
    let shown = e.to_string();
    assert!(
        shown.starts_with(PATH),
        "error does not start with the path: {shown}"
    );
}

/// Whether `GROUNDCAL_FUZZ_KNOWN_BUGS` is set: the findings listed as open
/// in `fuzz/README.md` are then let through, so that a run can look for new
/// ones before they are fixed. Only `check_input_error`'s empty-message check
/// (a TOML syntax error in a schedule gives an empty message) depends on it.
pub fn tolerate_known_bugs() -> bool {
    static KNOWN: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *KNOWN.get_or_init(|| std::env::var_os("GROUNDCAL_FUZZ_KNOWN_BUGS").is_some())
}

/// Whether two JSON values are the same up to floating-point parsing: numbers
/// may differ in the last bits, because serde_json's default float parser is
/// not correctly rounded (no `float_roundtrip` feature), so a value written by
/// `ryu` can read back a unit in the last place away.
pub fn json_close(a: &serde_json::Value, b: &serde_json::Value) -> bool {
    use serde_json::Value as V;
    match (a, b) {
        (V::Number(x), V::Number(y)) => match (x.as_f64(), y.as_f64()) {
            (Some(x), Some(y)) => {
                x == y || (x - y).abs() <= 4.0 * f64::EPSILON * x.abs().max(y.abs())
            }
            _ => x == y,
        },
        (V::Array(x), V::Array(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(x, y)| json_close(x, y))
        }
        (V::Object(x), V::Object(y)) => {
            x.len() == y.len()
                && x.iter()
                    .all(|(k, v)| y.get(k).is_some_and(|w| json_close(v, w)))
        }
        _ => a == b,
    }
}
