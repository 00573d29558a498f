//! The CDR decoder of the ROS 2 messages a bag brings (`groundcal-ros`):
//! the first byte picks the type, the rest is the message. A message that
//! decodes encodes to bytes that decode to the same bytes again (the
//! encoding is a function of the values; NaNs keep their bits), and nothing
//! panics or allocates beyond the input.
#![no_main]

use groundcal_ros::msg::{CameraInfo, Image, Message, PointCloud2, PoseFit, TfMessage};
use libfuzzer_sys::fuzz_target;

fn round_trip<M: Message>(bytes: &[u8]) {
    let Ok(message) = M::decode(bytes) else {
        return;
    };
    let encoded = message.encode();
    let again = M::decode(&encoded)
        .unwrap_or_else(|e| panic!("{}: its own encoding does not decode: {e}", M::NAME));
    assert_eq!(again.encode(), encoded, "{}: not a fixed point", M::NAME);
}

fuzz_target!(|data: &[u8]| {
    let Some((&kind, bytes)) = data.split_first() else {
        return;
    };
    match kind % 5 {
        0 => round_trip::<Image>(bytes),
        1 => round_trip::<CameraInfo>(bytes),
        2 => round_trip::<TfMessage>(bytes),
        3 => round_trip::<PointCloud2>(bytes),
        _ => round_trip::<PoseFit>(bytes),
    }
});
