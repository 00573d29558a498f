//! A recording's `session.json` (`recording::session::Session::parse`).
#![no_main]

use groundcal::formats::recording::fakenect_frame_len;
use groundcal::formats::recording::session::{check_feet, Session};
use groundcal_fuzz::{check_input_error, json_close, path, text_of};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = text_of(data);
    let session = match Session::parse(path(), &text) {
        Err(e) => return check_input_error(&e, &text),
        Ok(session) => session,
    };
    // What parse promises about a session it returns.
    assert_eq!(session.format, "groundcal-recording");
    assert_eq!(session.version, 1);
    check_feet(&session.home.feet_body_mm).expect("home feet accepted");
    assert!(session.home.commanded.is_finite());
    assert!(session.kinect.tilt_deg.is_finite());
    session
        .kinect
        .depth_model
        .validate()
        .expect("depth model accepted");
    let intrinsics = session.kinect.intrinsics;
    intrinsics.validate().expect("intrinsics accepted");
    // Opening a recording sizes its frames from these; that must not overflow.
    let frame = fakenect_frame_len(intrinsics.width, intrinsics.height);
    assert!(frame > 2 * intrinsics.width * intrinsics.height);
    if let Some(m) = &session.nominal_mount {
        m.validate().expect("nominal mount accepted");
    }

    // Written back out (as the recorder writes it) it reads back the same.
    let mut written = serde_json::to_string_pretty(&session).expect("a session serialises");
    written.push('\n');
    let again = Session::parse(path(), &written)
        .unwrap_or_else(|e| panic!("a written session does not read back: {e}\n{written}"));
    let (a, b) = (
        serde_json::to_value(&session).unwrap(),
        serde_json::to_value(&again).unwrap(),
    );
    assert!(
        json_close(&a, &b),
        "round trip changed the session:\n{a}\n{b}"
    );
});
