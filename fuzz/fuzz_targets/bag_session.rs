//! A ROS 2 bag read as a legged robot's session (`bag::read_bag`): the TF
//! tree and its chains from the body to each foot, the still spans, the
//! camera info and the images' heads, for a quadruped's four feet through
//! hips and knees (seeded with a small bag of `make_quadruped_bag.py
//! --tiny`). Arbitrary bytes give a session or an error that names the
//! file; nothing panics, and a session has a pose's feet for every foot.
#![no_main]

use std::io::Write;

use groundcal::solving::bag::{read_bag, BagOptions};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // read_bag reads a file, twice: the input goes to one of this process's own.
    let path = std::env::temp_dir().join(format!("groundcal-fuzz-bag-{}.mcap", std::process::id()));
    let Ok(mut file) = std::fs::File::create(&path) else {
        return;
    };
    if file.write_all(data).is_err() {
        return;
    }
    drop(file);
    let options = BagOptions {
        depth_topic: "/camera/depth/image_rect_raw".into(),
        foot_frames: ["lf_foot", "rf_foot", "lh_foot", "rh_foot"]
            .map(String::from)
            .to_vec(),
        ..BagOptions::default()
    };
    match read_bag(&path, &options) {
        Ok(session) => {
            assert_eq!(session.home_feet_mm.len(), 4);
            for pose in &session.poses {
                assert_eq!(pose.feet_body_mm.len(), 4);
                assert!(!pose.stamps.is_empty() && pose.stamps.len() <= options.frames_per_pose);
            }
        }
        Err(e) => assert!(!e.to_string().is_empty()),
    }
});
