//! The link to the lower computer as Wi-Fi really is: the shared sample
//! recording calibrated live against `groundcal sim-robot --replay` in its own
//! process, through its fault injection: loss of 0, 10, 30 and 50 %,
//! duplicates with reordering and delay spikes of up to 200 ms, a restart of
//! the lower computer, and a 3 s partition in the middle of a pose.
//!
//! Each run either completes with the fault-free run's result, number for
//! number, or aborts safely: the body halted, then sent home once the link
//! returned. The retransmissions the lower computer saw are printed (run with
//! `--nocapture`) and recorded in docs/reliability.md.

mod common;

use common::{shared, temp_dir};
use serde_json::Value;

struct Run {
    code: i32,
    /// The result on stdout (null when there is none).
    result: Value,
    /// What `calibrate` said on stderr.
    said: String,
    stats: Value,
    receipts: Vec<Value>,
}

/// One live calibration of the sample recording through these faults.
fn run(tag: &str, faults: &str, retries: u32) -> Run {
    let recording = shared().join("data/sample-12");
    let work = temp_dir(tag);
    let live = common::calibrate_live(
        &recording,
        &work,
        faults,
        &format!("retries = {retries}\nretry_interval_ms = 50"),
    );
    let (code, said, stderr, receipts) = (live.code, live.stderr, live.robot_stderr, live.receipts);
    let result = serde_json::from_str(&live.stdout).unwrap_or(Value::Null);
    let stats: Value = serde_json::from_str(
        stderr
            .lines()
            .find_map(|l| l.strip_prefix("sim-robot: stats "))
            .expect("the stats line"),
    )
    .unwrap();
    let receipts = std::fs::read_to_string(&receipts)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let _ = std::fs::remove_dir_all(&work);
    Run {
        code,
        result,
        said,
        stats,
        receipts,
    }
}

/// Retransmissions the lower computer received, over all its lives.
fn retransmissions(stats: &Value) -> u64 {
    stats["lives"]
        .as_array()
        .unwrap()
        .iter()
        .map(|life| {
            life["retransmissions"].as_u64().unwrap()
                + life["hello_retransmissions"].as_u64().unwrap()
        })
        .sum()
}

/// What the result says of the mount, to compare runs number for number.
fn mount_and_sigma(result: &Value) -> (Value, Value, Value) {
    (
        result["robot_from_sensor"].clone(),
        result["sigma"].clone(),
        result["summary"].clone(),
    )
}

#[test]
fn every_link_fault_completes_with_the_fault_free_result_or_aborts_safely() {
    let clean = run("link-clean", "seed=1", 10);
    assert_eq!(clean.code, 0, "{}", clean.said);
    let expected = mount_and_sigma(&clean.result);
    let mut figures = vec![format!(
        "no fault: accepted, {} retransmissions",
        retransmissions(&clean.stats)
    )];
    // At 50 % loss each way a request and its reply both pass with p = 1/4:
    // 60 attempts all failing is 3e-8 per request.
    for (tag, faults) in [
        ("loss10", "loss=0.1,seed=2"),
        ("loss30", "loss=0.3,seed=3"),
        ("loss50", "loss=0.5,seed=4"),
        ("jitter", "dup=0.2,reorder=0.2,delay_ms=200,seed=5"),
        ("restart", "restart_after_pose=6,seed=6"),
    ] {
        let faulty = run(&format!("link-{tag}"), faults, 60);
        assert_eq!(faulty.code, 0, "{faults}: {}", faulty.said);
        assert_eq!(
            mount_and_sigma(&faulty.result),
            expected,
            "{faults}: the result differs from the fault-free one"
        );
        figures.push(format!(
            "{faults}: accepted, the same result; {} retransmissions, faults {}",
            retransmissions(&faulty.stats),
            faulty.stats["faults"]
        ));
    }

    // 3 s without a word, from the start of the motion to pose 6; the link
    // gives up after 10 tries 50 ms apart, so the session fails, and the
    // robot is halted and sent home once the link returns.
    let cut = run("link-partition", "partition=6:3000,seed=7", 10);
    assert_eq!(
        cut.code, 1,
        "a lost link is a run-time failure: {}",
        cut.said
    );
    assert!(
        cut.said
            .contains("halted and sent home (the link came back after"),
        "{}",
        cut.said
    );
    let events: Vec<(String, String)> = cut
        .receipts
        .iter()
        .map(|r| {
            (
                r["event"].as_str().unwrap_or_default().to_string(),
                r["kind"].as_str().unwrap_or_default().to_string(),
            )
        })
        .collect();
    let partition = events
        .iter()
        .position(|(e, _)| e == "partition")
        .expect("the partition happened");
    let halt = events[partition..]
        .iter()
        .position(|(_, k)| k == "HALT")
        .map(|i| i + partition)
        .expect("HALT reached the lower computer after the partition");
    assert!(
        events[halt..].iter().any(|(_, k)| k == "HOME"),
        "HOME reached the lower computer after HALT"
    );
    assert!(
        cut.stats["faults"]["partitioned"].as_u64().unwrap() > 0,
        "{}",
        cut.stats
    );
    figures.push(format!(
        "partition=6:3000: aborted; HALT then HOME after the link returned; {} datagrams lost to the partition, {} retransmissions",
        cut.stats["faults"]["partitioned"],
        retransmissions(&cut.stats)
    ));
    eprintln!("link faults:\n  {}", figures.join("\n  "));
}
