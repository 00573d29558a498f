//! Configurations for a test: the simulator's with keys replaced, without its
//! noise table, on another schedule, with a depth pattern.

use super::*;

/// The robot's configuration (`config/groundcal.toml`) on the paper's
/// schedule, written into `dir`: what the shipped designed schedules were
/// designed against (`plan --design` compares with the configured one).
pub fn robot_config_on_the_papers_schedule(dir: &Path) -> PathBuf {
    let shipped = "schedule = \"schedules/designed-52.toml\"";
    let text = std::fs::read_to_string(root().join("config/groundcal.toml"))
        .expect("config/groundcal.toml");
    assert!(
        text.contains(shipped),
        "config/groundcal.toml lacks {shipped}"
    );
    let paper = root().join("config/schedules/octopus-52.toml");
    let path = dir.join("groundcal-octopus-52.toml");
    std::fs::create_dir_all(dir).expect("configuration directory");
    std::fs::write(
        &path,
        text.replace(shipped, &format!("schedule = \"{}\"", paper.display())),
    )
    .expect("configuration written");
    path
}

/// config/sim.toml with its schedule path made absolute and these
/// replacements (each must occur), written into `dir` as `groundcal.toml`.
pub fn sim_config(dir: &Path, replacements: &[(&str, &str)]) -> PathBuf {
    let mut text = std::fs::read_to_string(root().join("config/sim.toml"))
        .expect("config/sim.toml")
        .replace(
            "schedule = \"schedules/octopus-52.toml\"",
            &format!(
                "schedule = \"{}\"",
                root().join("config/schedules/octopus-52.toml").display()
            ),
        );
    for (from, to) in replacements {
        assert!(text.contains(from), "config/sim.toml has no {from}");
        text = text.replace(from, to);
    }
    let path = dir.join("groundcal.toml");
    std::fs::write(&path, text).expect("config written");
    path
}

/// [`sim_config`] as a real robot's configuration: without the noise
/// table nobody has measured on a real robot (`[calibration.noise]`).
pub fn sim_config_unmeasured(dir: &Path, replacements: &[(&str, &str)]) -> PathBuf {
    let path = sim_config(dir, replacements);
    let text = std::fs::read_to_string(&path).expect("the configuration written");
    let (before, rest) = text
        .split_once("[calibration.noise]")
        .expect("config/sim.toml has a noise table");
    let after = &rest[rest
        .find("[calibration.gates]")
        .expect("and gates after it")..];
    std::fs::write(&path, format!("{before}{after}")).expect("configuration written");
    path
}

/// A configuration written by [`sim_config`] moved onto another of
/// `config/schedules/` (its name without `.toml`), such as the robot's
/// `designed-52`.
pub fn on_schedule(config: &Path, schedule: &str) {
    let text = std::fs::read_to_string(config).expect("the configuration written");
    let paper = format!(
        "schedule = \"{}\"",
        root().join("config/schedules/octopus-52.toml").display()
    );
    assert!(text.contains(&paper), "{text}");
    let other = root().join(format!("config/schedules/{schedule}.toml"));
    std::fs::write(
        config,
        text.replace(&paper, &format!("schedule = \"{}\"", other.display())),
    )
    .expect("configuration written");
}

/// The line of config/sim.toml that names the simulated Kinect's depth model.
pub const SIM_DEPTH_MODEL_LINE: &str =
    "depth_model = { kind = \"inverse-linear\", a = 3.3309495161, b = -0.0030711016 }";

/// config/sim.toml's `[sim]` line that gives its Kinect no fixed pattern.
pub const SIM_NO_PATTERN_LINE: &str = "depth_distortion = { shape = \"none\" }";

/// config/sim.toml, unmeasured ([`sim_config_unmeasured`]), with the
/// simulated Kinect's depth carrying `pattern` (a `depth_distortion = {…}`
/// line, or "") and, with `zero_plane`, libfreenect's zero-plane model.
pub fn sim_config_with_pattern(dir: &Path, pattern: &str, zero_plane: bool) -> PathBuf {
    std::fs::create_dir_all(dir).expect("configuration directory");
    // "" keeps config/sim.toml's "none" (a missing line is the default,
    // the measured pattern).
    let mut replacements = if pattern.is_empty() {
        vec![]
    } else {
        vec![(SIM_NO_PATTERN_LINE, pattern)]
    };
    if zero_plane {
        replacements.push((SIM_DEPTH_MODEL_LINE, ""));
    }
    sim_config_unmeasured(dir, &replacements)
}
