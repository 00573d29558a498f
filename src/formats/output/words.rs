//! Numbers and lines for messages and the readable table.

/// A number for a message, short whatever its size: `1.0032`, `1e308`,
/// `-2.5e-9` (an input echoed back in full could run to 309 digits).
pub fn brief_number(value: f64) -> String {
    let plain = format!("{value}");
    if plain.len() <= 12 {
        plain
    } else {
        let scientific = format!("{value:.6e}");
        match scientific.split_once('e') {
            Some((mantissa, exponent)) if mantissa.contains('.') => format!(
                "{}e{exponent}",
                mantissa.trim_end_matches('0').trim_end_matches('.')
            ),
            _ => scientific,
        }
    }
}

#[cfg(test)]
mod brief_number_tests {
    use super::brief_number;

    #[test]
    fn numbers_in_messages_stay_short() {
        assert_eq!(brief_number(1.0032), "1.0032");
        assert_eq!(brief_number(1e308), "1e308");
        assert_eq!(brief_number(1e300), "1e300");
        assert_eq!(brief_number(-2.5e-9), "-2.5e-9");
        assert_eq!(brief_number(f64::MAX).len(), "1.797693e308".len());
        assert_eq!(brief_number(12345.678), "12345.678");
    }
}

/// Text for a terminal `width` columns wide: a longer line is broken at the
/// last space that fits (never inside a word), and its continuation is
/// indented under the line's text (past a leading "- " or "note: ").
pub fn wrap_words(text: &str, width: usize) -> String {
    let mut out = String::with_capacity(text.len() + 64);
    for line in text.split_inclusive('\n') {
        let (body, newline) = match line.strip_suffix('\n') {
            Some(b) => (b, "\n"),
            None => (line, ""),
        };
        if body.chars().count() <= width || width < 20 {
            out.push_str(line);
            continue;
        }
        let lead = body.len() - body.trim_start().len();
        let rest = &body[lead..];
        let bullet = ["- ", "note: "]
            .iter()
            .find(|b| rest.starts_with(**b))
            .map_or(0, |b| b.chars().count());
        let indent = " ".repeat((lead + bullet).min(width / 2));
        // Words as split at single spaces, so that runs of spaces (aligned
        // columns) are kept where the line is not broken.
        let mut current = " ".repeat(lead);
        let mut started = false;
        for word in rest.split(' ') {
            let length = current.chars().count() + usize::from(started) + word.chars().count();
            if started && length > width && !word.is_empty() {
                out.push_str(current.trim_end());
                out.push('\n');
                current = indent.clone();
                started = false;
            }
            if started {
                current.push(' ');
            }
            current.push_str(word);
            started = true;
        }
        out.push_str(current.trim_end());
        out.push_str(newline);
    }
    out
}

#[cfg(test)]
mod wrap_tests {
    use super::wrap_words;

    #[test]
    fn long_lines_break_between_words_under_their_text() {
        let text = "  - the angle β (pitch) is uncertain (σ = 0.120°, at most 0.100° allowed): calibrate again with the robot on open, flat ground\nshort\n";
        let wrapped = wrap_words(text, 40);
        for line in wrapped.lines() {
            assert!(line.chars().count() <= 40, "{line:?}");
        }
        let lines: Vec<&str> = wrapped.lines().collect();
        assert!(lines[0].starts_with("  - the angle"), "{wrapped}");
        assert!(
            lines[1].starts_with("    ") && !lines[1].starts_with("     "),
            "{wrapped}"
        );
        assert_eq!(*lines.last().unwrap(), "short");
        // No word is cut: the words are the same, in order.
        let words = |s: &str| s.split_whitespace().map(String::from).collect::<Vec<_>>();
        assert_eq!(words(&wrapped), words(text));
    }
}
