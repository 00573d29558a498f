//! Text for the report's HTML: escaping, and numbers as the page prints them.

/// Escapes text for HTML content and attribute values.
pub(super) fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
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
        assert_eq!(
            escape("<a href='x'>&\"</a>"),
            "&lt;a href=&#39;x&#39;&gt;&amp;&quot;&lt;/a&gt;"
        );
    }
}
