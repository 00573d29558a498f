//! The result document of `groundcal solve/replay --json` as read back by
//! `groundcal export` (`export::parse_result`, with and without
//! `allow_rejected`) and by the store and the daemon
//! (`output::ResultJson::parse`, on any input that is JSON).
#![no_main]

use groundcal::formats::export::{parse_result, ExportError};
use groundcal::formats::output::{ResultJson, ResultStatus};
use groundcal_fuzz::{check_input_error, json_close, path, text_of};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = text_of(data);
    let value: Option<serde_json::Value> = serde_json::from_str(&text).ok();
    let result = value.map(ResultJson::parse);

    if let Some(Err(message)) = &result {
        // It names the key (`"robot_from_sensor.pz_mm" is null, …`).
        assert!(
            message.starts_with('"') || message.starts_with("not a groundcal result document"),
            "error does not name the key: {message}"
        );
    }

    for allow_rejected in [false, true] {
        let parsed = parse_result(path(), &text, allow_rejected);
        // Whatever it returns agrees with ResultJson::parse.
        match (&parsed, &result) {
            (Err(ExportError::Input(e)), _) => {
                check_input_error(e, &text);
                match &result {
                    None => assert!(
                        e.message.starts_with("not a groundcal result document"),
                        "JSON syntax error: {e}"
                    ),
                    Some(Err(message)) => {
                        assert_eq!(&e.message, message);
                        assert_eq!(e.line, None);
                    }
                    Some(Ok(r)) => match &r.robot_from_sensor {
                        None => assert!(
                            e.message.contains("\"robot_from_sensor\" is missing"),
                            "{e}"
                        ),
                        Some(_) => assert!(
                            e.message.contains("disagree")
                                && e.message.starts_with("\"robot_from_sensor."),
                            "a result with parameters refused: {e}"
                        ),
                    },
                }
            }
            (Err(ExportError::Rejected { path: p, reasons }), Some(Ok(r))) => {
                assert!(!allow_rejected, "rejected although allowed");
                assert_eq!(r.status, ResultStatus::Rejected);
                assert_eq!(p, path());
                assert_eq!(reasons, &r.reasons);
                let shown = parsed.as_ref().unwrap_err().to_string();
                assert!(shown.starts_with(groundcal_fuzz::PATH), "{shown}");
            }
            (Err(e @ ExportError::Rejected { .. }), _) => {
                panic!("rejected, but ResultJson::parse gives {result:?}: {e}")
            }
            (Ok(pose), Some(Ok(r))) => {
                assert!(allow_rejected || r.status == ResultStatus::Accepted);
                let m = r.robot_from_sensor.as_ref().expect("parameters exported");
                let got = [
                    pose.alpha_deg,
                    pose.beta_deg,
                    pose.gamma_deg,
                    pose.px_mm,
                    pose.py_mm,
                    pose.pz_mm,
                ];
                let want = [m.alpha_deg, m.beta_deg, m.gamma_deg, m.px_mm, m.py_mm, m.pz_mm];
                assert_eq!(got, want);
                assert!(got.iter().all(|v| v.is_finite()), "{got:?}");
            }
            (Ok(pose), _) => panic!("exported {pose:?}, but ResultJson::parse gives {result:?}"),
        }
    }

    // A document that reads, written back as groundcal writes it
    // (`to_string_pretty` + newline), reads back the same, and export decides
    // the same about it.
    if let Some(Ok(r)) = &result {
        let mut written = serde_json::to_string_pretty(r).expect("a result serialises");
        written.push('\n');
        let again = serde_json::from_str(&written)
            .map_err(|e| e.to_string())
            .and_then(ResultJson::parse)
            .unwrap_or_else(|e| panic!("a written result does not read back: {e}\n{written}"));
        let (a, b) = (
            serde_json::to_value(r).unwrap(),
            serde_json::to_value(&again).unwrap(),
        );
        assert!(json_close(&a, &b), "round trip changed the result:\n{a}\n{b}");
        for allow_rejected in [false, true] {
            let before = parse_result(path(), &text, allow_rejected);
            let after = parse_result(path(), &written, allow_rejected);
            assert_eq!(
                before.is_ok(),
                after.is_ok(),
                "export of the written result differs: {before:?} / {after:?}"
            );
        }
    }
});
