//! `groundcal solve`'s input, a `groundcal-planes` JSON document
//! (`recording::planes::parse_planes`).
#![no_main]

use groundcal_fuzz::{check_input_error, path, text_of};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = text_of(data);
    match groundcal::formats::recording::planes::parse_planes(path(), &text) {
        Err(e) => check_input_error(&e, &text),
        Ok(observations) => {
            // A document that parses has as many observations as it lists,
            // with distinct indices.
            let doc: serde_json::Value = serde_json::from_str(&text).expect("parsed twice");
            assert_eq!(
                observations.len(),
                doc["observations"].as_array().map_or(0, Vec::len)
            );
            assert!(!observations.is_empty());
            let mut indices: Vec<u32> = observations.iter().map(|o| o.index).collect();
            indices.sort_unstable();
            indices.dedup();
            assert_eq!(indices.len(), observations.len(), "repeated index accepted");
            for o in &observations {
                // Planes come out normalised and oriented to d >= 0.
                let n = o.plane.normal;
                assert!(
                    n.iter().all(|v| v.is_finite()) && (n.norm() - 1.0).abs() < 1e-9,
                    "observation {}: plane normal {n:?} is not a unit vector (|n| = {})",
                    o.index,
                    n.norm()
                );
                assert!(
                    o.plane.d.is_finite() && o.plane.d >= 0.0,
                    "observation {}: plane d = {} is not finite and >= 0",
                    o.index,
                    o.plane.d
                );
                // The body pose is a proper rigid transform.
                let t = &o.ground_from_robot;
                assert!(
                    t.translation.vector.iter().all(|v| v.is_finite()),
                    "observation {}: translation {:?} is not finite",
                    o.index,
                    t.translation.vector
                );
                let h = t.to_homogeneous();
                let m = h.fixed_view::<3, 3>(0, 0).clone_owned();
                assert!(
                    m.iter().all(|v| v.is_finite()) && (m.determinant() - 1.0).abs() < 1e-9,
                    "observation {}: rotation {m:?} is not a rotation",
                    o.index
                );
            }
        }
    }
});
