//! The MCAP stream reader of `replay BAG.mcap` (`bag::stream`) on arbitrary
//! bytes, with every message it yields decoded as its schema says: errors
//! give an offset within the input, nothing panics, and no chunk or record
//! is allocated beyond the limits.
#![no_main]

use groundcal::solving::bag::stream::{for_each_message, Limits, ReadError};
use groundcal_ros::msg::{CameraInfo, Image, Message, TfMessage};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let limits = Limits {
        record_bytes: 1 << 20,
        chunk_bytes: 1 << 20,
    };
    let mut seen = 0u64;
    let read = for_each_message(data, limits, |_| true, |m| -> Result<(), ()> {
        seen += 1;
        assert!(m.data.len() < data.len().max(1) << 12, "a message larger than its input could hold");
        match m.schema {
            "sensor_msgs/msg/Image" => drop(Image::decode(m.data)),
            "sensor_msgs/msg/CameraInfo" => drop(CameraInfo::decode(m.data)),
            "tf2_msgs/msg/TFMessage" => drop(TfMessage::decode(m.data)),
            _ => {}
        }
        Ok(())
    });
    match read {
        Ok(counts) => assert_eq!(counts.messages, seen),
        Err(ReadError::Stream(e)) => {
            assert!(e.offset <= data.len() as u64, "offset {} beyond {} bytes", e.offset, data.len());
            assert!(!e.what.is_empty());
        }
        Err(ReadError::Stopped(())) => unreachable!("the callback never stops"),
    }
});
