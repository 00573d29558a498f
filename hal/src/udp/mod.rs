//! The lower computer over UDP (`shared/spec/hexapod-udp.md`), in the manner
//! of ntpd-rs: the protocol is pure state machines that take bytes and time
//! and give datagrams and events ([`proto`], [`client`], [`server`]); thin
//! tokio tasks own the sockets and the clock ([`link`]; the simulated lower
//! computer's task is in `crate::sim::lower_computer`).
//!
//! - [`proto`]: the datagrams, and a decoder that never panics;
//! - [`client`]: the upper computer's side: retransmission, duplicates and
//!   stale replies, session renewal, keep-alives;
//! - [`server`]: the lower computer's side: sessions, idempotence, limits,
//!   the watchdog;
//! - [`link`]: the socket, the task, and [`UdpBodyController`].
//!
//! Nothing here knows the simulator: it serves any [`server::Body`].

pub mod client;
pub mod link;
pub mod proto;
pub mod server;

pub use link::{LinkConfig, UdpBodyController, UdpError};
pub use proto::{decode, DecodeError};
