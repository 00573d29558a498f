//! Pieces of the report's HTML: the parameters' names, and numbers as the
//! page prints them. Escaping is maud's: every `(value)` in `html!` is
//! escaped, and only the page's own style sheet is inserted as it is.

use maud::{html, Markup};

/// The six parameters' names as the page writes them: the positions with
/// their axis as a subscript (p<sub>x</sub>).
pub(super) fn param_name(k: usize) -> Markup {
    const NAMES: [(&str, Option<&str>); 6] = [
        ("α", None),
        ("β", None),
        ("γ", None),
        ("p", Some("x")),
        ("p", Some("y")),
        ("p", Some("z")),
    ];
    let (base, axis) = NAMES[k];
    html! { (base) @if let Some(axis) = axis { sub { (axis) } } }
}

/// e<sub>d</sub>, the paper's distance error.
pub(super) fn e_d() -> Markup {
    html! { "e" sub { "d" } }
}

/// A number with fixed decimals, or a dash where there is none (NaN, ∞).
pub(super) fn num(value: f64, decimals: usize) -> String {
    if value.is_finite() {
        format!("{value:.decimals$}")
    } else {
        "—".to_string()
    }
}

/// [`num`] with its sign always written (`+0.12`, `-0.12`): a signed
/// difference. A value that rounds to zero has none (`0.00`, never `-0.00`).
pub(super) fn signed(value: f64, decimals: usize) -> String {
    if !value.is_finite() {
        return "—".to_string();
    }
    let text = format!("{value:+.decimals$}");
    if text[1..].chars().all(|c| c == '0' || c == '.') {
        text[1..].to_string()
    } else {
        text
    }
}

/// [`num`] of a value that may be missing.
pub(super) fn opt(value: Option<f64>, decimals: usize) -> String {
    value.map_or_else(|| "—".to_string(), |v| num(v, decimals))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signed_numbers() {
        assert_eq!(signed(0.126, 2), "+0.13");
        assert_eq!(signed(-3.5, 1), "-3.5");
        assert_eq!(signed(-0.0004, 3), "0.000");
        assert_eq!(signed(0.0, 0), "0");
        assert_eq!(signed(f64::NAN, 2), "—");
        assert_eq!(num(f64::INFINITY, 2), "—");
        assert_eq!(param_name(4).into_string(), "p<sub>y</sub>");
        assert_eq!(param_name(1).into_string(), "β");
    }
}
