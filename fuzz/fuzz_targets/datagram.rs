//! The lower computer's datagrams (hexapod-udp.md): `udp::proto::decode` on
//! arbitrary bytes never panics, and whatever it accepts re-encodes to bytes
//! that decode to the same datagram (compared as bytes, so NaN payloads count).
#![no_main]

use groundcal_hal::udp::proto::{decode, encode};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|bytes: &[u8]| {
    if let Ok(datagram) = decode(bytes) {
        let encoded = encode(&datagram);
        let again = decode(&encoded).expect("an encoded datagram decodes");
        assert_eq!(encode(&again), encoded, "encode/decode is not stable");
    }
});
