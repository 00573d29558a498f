//! The choices a word makes, in the file or on the command line: where the
//! lower computer is (`robot.address`, `--robot`), where depth comes from
//! (`sensor.source`, `--sensor`) and which simulated world (`sim.world`);
//! each read from its words with an error that names them.

use super::*;

/// Where the lower computer is (`robot.address`, `--robot`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RobotAddress {
    /// The simulated lower computer, in process.
    Sim,
    /// A lower computer at `host:port` (hexapod-udp.md), resolved when the
    /// link opens, IPv4 first.
    HostPort(String),
}

impl FromStr for RobotAddress {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        if text == "sim" {
            return Ok(Self::Sim);
        }
        // A host name is allowed too; it must at least have a host and a port.
        let host_and_port = text
            .rsplit_once(':')
            .filter(|(host, _)| !host.is_empty())
            .and_then(|(_, port)| port.parse::<u16>().ok())
            .is_some();
        if text.parse::<std::net::SocketAddr>().is_ok() || host_and_port {
            Ok(Self::HostPort(text.to_string()))
        } else {
            Err(format!("\"{text}\" is neither `sim` nor host:port"))
        }
    }
}

impl fmt::Display for RobotAddress {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Sim => f.write_str("sim"),
            Self::HostPort(address) => f.write_str(address),
        }
    }
}

/// Where depth frames come from (`sensor.source`, `--sensor`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SensorSource {
    /// A Kinect v1 through libfreenect.
    Kinect,
    /// The simulated Kinect, seeing the simulated world.
    Sim,
    /// The frames of a recording played back pose by pose, as if live
    /// (`replay:DIR`, the spelling of cli.md).
    Playback(PathBuf),
}

impl FromStr for SensorSource {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        match text {
            "kinect" => Ok(Self::Kinect),
            "sim" => Ok(Self::Sim),
            _ => match text.strip_prefix("replay:") {
                Some(dir) if !dir.is_empty() => Ok(Self::Playback(PathBuf::from(dir))),
                _ => Err(format!("\"{text}\" is not kinect, sim or replay:DIR")),
            },
        }
    }
}

impl fmt::Display for SensorSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Kinect => f.write_str("kinect"),
            Self::Sim => f.write_str("sim"),
            Self::Playback(dir) => write!(f, "replay:{}", dir.display()),
        }
    }
}

/// The simulated world (`sim.world`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SimWorld {
    /// Flat ground, nothing else.
    Flat,
    /// Boxes on the ground and a wall in view.
    BoxesAndWall,
    /// Ground with 1 cm bumps.
    Uneven,
    /// A corridor with people: the floor a tenth of the view.
    Corridor,
    /// Four boxes and a wall across the far end of the view.
    Clutter,
    /// Boxes 5–10 cm tall, their tops near the floor.
    LowBoxes,
    /// A wall meeting the floor in view.
    WallMeetingFloor,
}

impl SimWorld {
    const NAMES: [(&'static str, SimWorld); 7] = [
        ("flat", SimWorld::Flat),
        ("boxes-and-wall", SimWorld::BoxesAndWall),
        ("uneven", SimWorld::Uneven),
        ("corridor", SimWorld::Corridor),
        ("clutter", SimWorld::Clutter),
        ("low-boxes", SimWorld::LowBoxes),
        ("wall-meeting-floor", SimWorld::WallMeetingFloor),
    ];
}

impl FromStr for SimWorld {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        Self::NAMES
            .iter()
            .find(|(name, _)| *name == text)
            .map(|(_, world)| *world)
            .ok_or_else(|| {
                let names: Vec<&str> = Self::NAMES.iter().map(|(name, _)| *name).collect();
                format!("\"{text}\" is not one of {}", names.join(", "))
            })
    }
}

impl fmt::Display for SimWorld {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let name = Self::NAMES
            .iter()
            .find(|(_, world)| world == self)
            .map_or("?", |(name, _)| name);
        f.write_str(name)
    }
}

/// A string value parsed as `T`, an error naming `key` (the TOML error adds
/// the file and line).
pub(super) fn parsed<'de, D: Deserializer<'de>, T: FromStr<Err = String>>(
    deserializer: D,
    key: &str,
) -> Result<T, D::Error> {
    let text = String::deserialize(deserializer)?;
    text.parse()
        .map_err(|e| serde::de::Error::custom(format!("{key}: {e}")))
}

pub(super) fn robot_address<'de, D: Deserializer<'de>>(d: D) -> Result<RobotAddress, D::Error> {
    parsed(d, "robot.address")
}

pub(super) fn sensor_source<'de, D: Deserializer<'de>>(d: D) -> Result<SensorSource, D::Error> {
    parsed(d, "sensor.source")
}

pub(super) fn sim_world<'de, D: Deserializer<'de>>(d: D) -> Result<SimWorld, D::Error> {
    parsed(d, "sim.world")
}
