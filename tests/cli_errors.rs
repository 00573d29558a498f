//! Bad input to the command line: a clear message naming the file, line or
//! flag, exit status 2, and never a panic.

mod common;

use std::io::Write;

use common::groundcal;

fn temp_file(contents: &[u8]) -> tempfile_path::TempPath {
    tempfile_path::TempPath::new(contents)
}

/// A minimal temporary file that removes itself.
mod tempfile_path {
    use std::path::PathBuf;
    use std::sync::atomic::{AtomicUsize, Ordering};

    pub struct TempPath(pub PathBuf);

    impl TempPath {
        pub fn new(contents: &[u8]) -> Self {
            static COUNTER: AtomicUsize = AtomicUsize::new(0);
            let path = std::env::temp_dir().join(format!(
                "groundcal-test-{}-{}",
                std::process::id(),
                COUNTER.fetch_add(1, Ordering::Relaxed)
            ));
            std::fs::write(&path, contents).unwrap();
            Self(path)
        }

        pub fn as_str(&self) -> &str {
            self.0.to_str().unwrap()
        }
    }

    impl Drop for TempPath {
        fn drop(&mut self) {
            let _ = std::fs::remove_file(&self.0);
        }
    }
}

fn assert_bad_input(args: &[&str], must_mention: &[&str]) {
    let (code, stdout, stderr) = groundcal(args);
    assert_eq!(code, 2, "args {args:?}: stderr {stderr}");
    assert!(stdout.is_empty(), "nothing on stdout on error: {stdout}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    for word in must_mention {
        assert!(
            stderr.contains(word),
            "stderr does not mention {word:?}: {stderr}"
        );
    }
}

/// A FIFO given as an input file is refused at once (a read of it would
/// wait for a writer for ever), naming it: the planes of `solve`, the
/// configuration of `check-config` and `plan`.
#[test]
fn a_fifo_as_an_input_file_is_refused_not_waited_on() {
    let dir = std::env::temp_dir().join(format!("groundcal-fifo-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let fifo = dir.join("input");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap();
    assert!(made.success());
    let path = fifo.to_str().unwrap();
    for args in [
        vec!["solve", path],
        vec!["check-config", path],
        vec!["plan", "--config", path],
    ] {
        let (code, _, stderr) = common::groundcal_within(&args, std::time::Duration::from_secs(10));
        assert_eq!(code, 2, "{args:?} (-1: killed after 10 s): {stderr}");
        assert!(
            stderr.contains(path) && stderr.contains("a FIFO"),
            "{args:?}: {stderr}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A result printed to a closed standard output (`>&-`) is a failure, exit
/// 1, said on stderr; to `/dev/null` it is printed as asked (exit 0),
/// whether opened for writing (a shell's `>`) or for reading and writing (a
/// shell's `<>`, Python's `subprocess.DEVNULL`, a supervisor's null output).
#[test]
fn a_result_printed_to_a_closed_output_is_a_failure() {
    let sample = common::shared().join("data/sample-12");
    let run = |redirect: &str| {
        let out = std::process::Command::new("sh")
            .arg("-c")
            .arg(format!("exec \"$0\" replay \"$1\" --json {redirect}"))
            .arg(env!("CARGO_BIN_EXE_groundcal"))
            .arg(&sample)
            .output()
            .unwrap();
        (
            out.status.code().unwrap_or(-1),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (code, stderr) = run(">&-");
    assert_eq!(code, 1, "{stderr}");
    assert!(stderr.contains("standard output is closed"), "{stderr}");
    let (code, stderr) = run(">/dev/null");
    assert_eq!(code, 0, "{stderr}");
    let (code, stderr) = run("1<>/dev/null");
    assert_eq!(code, 0, "{stderr}");
}

/// `--mcap` into a directory that does not exist is refused before anything
/// is replayed, as any other unwritable path; the directory is not made.
#[test]
fn an_mcap_path_in_a_missing_directory_is_refused() {
    let missing =
        std::env::temp_dir().join(format!("groundcal-no-such-dir-{}", std::process::id()));
    let path = missing.join("x.mcap");
    let sample = common::shared().join("data/sample-12");
    let (code, stdout, stderr) = groundcal(&[
        "replay",
        sample.to_str().unwrap(),
        "--json",
        "--mcap",
        path.to_str().unwrap(),
    ]);
    assert_eq!(code, 1, "{stderr}");
    assert!(stdout.is_empty(), "{stdout}");
    assert!(
        stderr.contains("x.mcap: cannot create: its directory")
            && stderr.contains("does not exist"),
        "{stderr}"
    );
    assert!(!missing.exists(), "the missing directory was made");
}

#[test]
fn solve_names_a_missing_file() {
    assert_bad_input(
        &["solve", "/nonexistent/planes.json", "--json"],
        &["/nonexistent/planes.json", "cannot open"],
    );
}

#[test]
fn solve_names_the_line_of_broken_json() {
    let f = temp_file(
        b"{\"format\": \"groundcal-planes\",\n \"version\": 1,\n \"observations\": [ oops ]}",
    );
    assert_bad_input(&["solve", f.as_str()], &[&format!("{}:3:", f.as_str())]);
}

#[test]
fn solve_refuses_a_wrong_version_and_non_finite_numbers() {
    let f = temp_file(br#"{"format": "groundcal-planes", "version": 7, "observations": []}"#);
    assert_bad_input(&["solve", f.as_str()], &["version 7"]);
    let f = temp_file(
        br#"{"format": "groundcal-planes", "version": 1, "observations": [{"index": 1,
        "robot_pose": {"alpha_deg": 0, "beta_deg": 0, "gamma_deg": 0, "px_mm": 0, "py_mm": 600, "pz_mm": 0},
        "plane": {"a": 0, "b": 0, "c": 0, "d_m": 1}}]}"#,
    );
    assert_bad_input(&["solve", f.as_str()], &["observations[0]", "normal"]);
}

#[test]
fn solve_survives_arbitrary_bytes() {
    let mut bytes = Vec::new();
    for i in 0..4096u32 {
        bytes
            .write_all(&(i.wrapping_mul(2654435761)).to_le_bytes())
            .unwrap();
    }
    let f = temp_file(&bytes);
    assert_bad_input(&["solve", f.as_str()], &[f.as_str()]);
}

#[test]
fn plane_names_bad_flags_and_files() {
    let tiff =
        common::shared().join("data/real/pcl_floor_tilted_frame_20121214T142255.814212_depth.tiff");
    let tiff = tiff.to_str().unwrap();
    assert_bad_input(
        &["plane", tiff, "--units", "inches"],
        &["--units", "inches"],
    );
    assert_bad_input(&["plane", tiff, "--model", "cubic"], &["--model", "cubic"]);
    assert_bad_input(&["plane", tiff, "--up", "0,1"], &["--up"]);
    assert_bad_input(&["plane", tiff, "--fx", "-5"], &["focal"]);
    assert_bad_input(
        &["plane", tiff, "--up-tolerance", "120"],
        &["--up-tolerance"],
    );
    let f = temp_file(b"P5 640 480 65535\n\x01\x02");
    assert_bad_input(&["plane", f.as_str()], &[f.as_str(), "614400"]);
}

#[test]
fn unknown_commands_and_flags_are_usage_errors() {
    let (code, _, stderr) = groundcal(&["solve"]);
    assert_eq!(code, 2, "{stderr}");
    let (code, _, _) = groundcal(&["frobnicate"]);
    assert_eq!(code, 2);
}

/// The hardware flags and keys are typed: a value that is not one of them is
/// bad input (exit 2) naming the flag or the key, before anything is opened.
#[test]
fn hardware_choices_that_do_not_exist_are_named() {
    assert_bad_input(
        &["calibrate", "--robot", "sim", "--sensor", "bogus"],
        &["--sensor", "bogus", "kinect, sim or replay:DIR"],
    );
    assert_bad_input(
        &["calibrate", "--robot", "", "--sensor", "sim"],
        &["--robot", "neither `sim` nor host:port"],
    );
    assert_bad_input(
        &["serve", "--config", "x", "--sensor", "replay:"],
        &["--sensor"],
    );
    assert_bad_input(
        &[
            "capture",
            "--sensor",
            "camera",
            "--frames",
            "1",
            "--out",
            "/nonexistent",
        ],
        &["--sensor", "camera"],
    );
    let shipped = std::fs::read_to_string(
        std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("config/sim.toml"),
    )
    .unwrap();
    for (from, to, key) in [
        ("source = \"sim\"", "source = \"webcam\"", "sensor.source"),
        ("address = \"sim\"", "address = \"robot\"", "robot.address"),
        ("world = \"flat\"", "world = \"moon\"", "sim.world"),
    ] {
        assert!(shipped.contains(from), "config/sim.toml has {from}");
        let dir =
            std::env::temp_dir().join(format!("groundcal-typed-{}-{key}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let config = dir.join("groundcal.toml");
        let schedule = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("config/schedules/octopus-52.toml");
        let text = shipped
            .replace(from, to)
            .replace("schedules/octopus-52.toml", schedule.to_str().unwrap());
        std::fs::write(&config, text).unwrap();
        let config = config.to_str().unwrap();
        assert_bad_input(&["check-config", config], &[key, config]);
        assert_bad_input(&["calibrate", "--config", config], &[key]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
