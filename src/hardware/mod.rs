//! The hardware a session runs on, chosen at run time from the configuration
//! and the `--robot` / `--sensor` overrides.

pub mod replay_sensor;
