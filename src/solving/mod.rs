//! Calibrations from poses already visited: the drift check against a
//! calibration, a recording replayed, the motor's tilts joined, a session as
//! MCAP, and other robots' ROS 2 bags. The live session
//! ([`crate::session`]) uses the drift check; nothing here uses the session.

pub mod bag;
pub mod mcap_session;
pub mod replay;
pub mod tilts;
pub mod verify;
