//! ROS 2 messages as groundcal writes them into MCAP files (Foxglove,
//! `ros2 bag`) and reads them from bags made by other robots' stacks.
//!
//! - [`cdr`]: the Common Data Representation (OMG XCDR1, plain, as ROS 2's
//!   middleware puts messages on the wire and rosbag2 stores them);
//! - [`msg`]: the messages groundcal uses, each with its `ros2msg`
//!   definition (dependencies included, as MCAP's `ros2msg` schema
//!   encoding wants) and its encoder and decoder.
//!
//! No I/O: values in, bytes out, and back.

pub mod cdr;
pub mod msg;

pub use cdr::{CdrError, CdrReader, CdrWriter};
pub use msg::Message;
