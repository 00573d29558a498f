//! The machine groundcal runs on: files read with a bound and written whole
//! or not at all, bad input named wherever it comes from, and systemd's
//! notify and watchdog. The lowest floor of the application: it uses
//! nothing else of it.

pub mod files;
pub mod input;
pub mod systemd;
