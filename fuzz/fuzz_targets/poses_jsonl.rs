//! A recording's `poses.jsonl` (`recording::poses::parse_poses`).
#![no_main]

use groundcal::formats::recording::poses::parse_poses;
use groundcal::formats::recording::session::check_feet;
use groundcal_fuzz::{check_input_error, json_close, path, text_of};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = text_of(data);
    let file = match parse_poses(path(), &text) {
        Err(e) => return check_input_error(&e, &text),
        Ok(file) => file,
    };
    // What parse promises about the poses it returns.
    let lines = text.split_inclusive('\n').count();
    let mut previous_line = 0;
    let mut indices = std::collections::HashSet::new();
    for pose in &file.poses {
        assert!(pose.index >= 1, "pose index 0 accepted");
        assert!(indices.insert(pose.index), "pose {} twice", pose.index);
        assert!(pose.commanded.is_finite());
        check_feet(&pose.feet_body_mm).expect("feet accepted");
        for name in &pose.depth_frames {
            assert!(
                !name.is_empty() && name != ".." && !name.contains(['/', '\\']),
                "frame name {name:?} is not a plain file name"
            );
        }
        assert!(
            pose.line > previous_line && pose.line <= lines,
            "pose {} on line {} (previous {previous_line}, {lines} lines)",
            pose.index,
            pose.line
        );
        previous_line = pose.line;
    }
    // A record cut off part-way (newline or not) is the last one.
    if let Some(c) = file.cut_off {
        let last_record = text.trim_end().rfind('\n').map_or(0, |i| i + 1);
        assert_eq!(c.byte, last_record, "a cut-off record that is not the last: {c:?}");
        assert!(c.line > previous_line && c.line <= lines, "cut-off line {c:?}, {lines} lines");
        assert!(c.written > 0 && c.byte + c.written <= text.len(), "cut-off bytes {c:?}");
    }

    // Written back one line each (as the recorder writes them) they read back
    // the same, with nothing torn.
    let mut written = String::new();
    for pose in &file.poses {
        written.push_str(&serde_json::to_string(pose).expect("a pose serialises"));
        written.push('\n');
    }
    let again = parse_poses(path(), &written)
        .unwrap_or_else(|e| panic!("written poses do not read back: {e}\n{written}"));
    assert!(again.cut_off.is_none(), "written poses read back cut off");
    let (a, b) = (
        serde_json::to_value(&file.poses).unwrap(),
        serde_json::to_value(&again.poses).unwrap(),
    );
    assert!(
        json_close(&a, &b),
        "round trip changed the poses:\n{a}\n{b}"
    );
});
