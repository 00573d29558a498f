//! The datagrams of `shared/spec/hexapod-udp.md`, version 1: encoding and a
//! decoder that accepts only well-formed datagrams.
//!
//! Layout (little-endian): a 16-byte header (`"HX"`, version, type, session,
//! seq, payload length, flags), the payload, then a CRC-32 (IEEE 802.3, as
//! zlib's `crc32`) of everything before it. [`decode`] never panics: any byte
//! string is either a [`Datagram`] or a [`DecodeError`] saying what is wrong.
//! Errors found after the header and CRC were verified carry the [`Header`],
//! so that the lower computer can answer a malformed request with ACK 4.

use std::fmt;

use crate::controller::MotionState;

/// The first two bytes of every datagram.
pub const MAGIC: [u8; 2] = *b"HX";
/// The protocol version this module speaks.
pub const VERSION: u8 = 1;
/// Bytes before the payload.
pub const HEADER_LEN: usize = 16;
/// Bytes of the trailing CRC.
pub const CRC_LEN: usize = 4;
/// The longest datagram of version 1 (a STATE); a receive buffer of this size
/// or more sees every valid datagram whole.
pub const MAX_DATAGRAM_LEN: usize = HEADER_LEN + STATE_LEN + CRC_LEN;

const SET_POSE_LEN: usize = 32;
const WELCOME_LEN: usize = 40;
const STATE_LEN: usize = 84;

/// Message type codes (the header's `type`).
pub mod kind {
    pub const HELLO: u8 = 0x01;
    pub const SET_POSE: u8 = 0x02;
    pub const GET_STATE: u8 = 0x03;
    pub const HOME: u8 = 0x04;
    pub const HALT: u8 = 0x05;
    pub const BYE: u8 = 0x06;
    pub const WELCOME: u8 = 0x81;
    pub const ACK: u8 = 0x82;
    pub const STATE: u8 = 0x83;

    /// Whether `code` is a request (upper → lower computer).
    pub fn is_request(code: u8) -> bool {
        (HELLO..=BYE).contains(&code)
    }

    /// Whether `code` is a reply (lower → upper computer).
    pub fn is_reply(code: u8) -> bool {
        (WELCOME..=STATE).contains(&code)
    }

    /// The message's name as the spec writes it, for logs.
    pub fn name(code: u8) -> &'static str {
        match code {
            HELLO => "HELLO",
            SET_POSE => "SET_POSE",
            GET_STATE => "GET_STATE",
            HOME => "HOME",
            HALT => "HALT",
            BYE => "BYE",
            WELCOME => "WELCOME",
            ACK => "ACK",
            STATE => "STATE",
            _ => "unknown",
        }
    }
}

/// A datagram's header fields, as received.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Header {
    /// The message type code ([`kind`]).
    pub kind: u8,
    pub session: u32,
    pub seq: u32,
    pub payload_len: u16,
    /// Reserved; sent as 0, ignored when received.
    pub flags: u16,
}

/// SET_POSE: a body pose (`ground_from_robot`, degrees and millimetres) to
/// reach in `duration_ms`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SetPose {
    pub pose_id: u16,
    pub alpha_deg: f32,
    pub beta_deg: f32,
    pub gamma_deg: f32,
    pub px_mm: f32,
    pub py_mm: f32,
    pub pz_mm: f32,
    pub duration_ms: u32,
}

/// WELCOME: the session granted, the HELLO's nonce, the limits and firmware.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WelcomePayload {
    pub session: u32,
    pub nonce: u32,
    pub max_tilt_deg: f32,
    pub min_height_mm: f32,
    pub max_height_mm: f32,
    pub max_shift_mm: f32,
    /// UTF-8, zero-padded; see [`WelcomePayload::firmware_text`].
    pub firmware: [u8; 16],
}

impl WelcomePayload {
    /// The firmware name: the bytes before the first zero, invalid UTF-8
    /// replaced (a garbled name must not cost the session).
    pub fn firmware_text(&self) -> String {
        let end = self
            .firmware
            .iter()
            .position(|&b| b == 0)
            .unwrap_or(self.firmware.len());
        String::from_utf8_lossy(&self.firmware[..end]).into_owned()
    }

    /// A zero-padded firmware field from text, cut at a character boundary
    /// to 16 bytes.
    pub fn firmware_field(text: &str) -> [u8; 16] {
        let mut field = [0u8; 16];
        let mut end = text.len().min(16);
        while !text.is_char_boundary(end) {
            end -= 1;
        }
        field[..end].copy_from_slice(&text.as_bytes()[..end]);
        field
    }
}

/// ACK status codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AckStatus {
    Accepted = 0,
    OutsideLimits = 1,
    RefusedInState = 2,
    UnknownSession = 3,
    Malformed = 4,
}

impl AckStatus {
    /// The status of a wire code, if it is one of version 1's.
    pub fn from_code(code: u8) -> Option<Self> {
        Some(match code {
            0 => Self::Accepted,
            1 => Self::OutsideLimits,
            2 => Self::RefusedInState,
            3 => Self::UnknownSession,
            4 => Self::Malformed,
            _ => return None,
        })
    }

    pub fn code(self) -> u8 {
        self as u8
    }

    /// What the status means, in an operator's words.
    pub fn describe(self) -> &'static str {
        match self {
            Self::Accepted => "accepted",
            Self::OutsideLimits => "outside the limits",
            Self::RefusedInState => "refused in this state (fault or halted)",
            Self::UnknownSession => "unknown session",
            Self::Malformed => "malformed payload",
        }
    }
}

impl fmt::Display for AckStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ACK {} ({})", self.code(), self.describe())
    }
}

/// STATE: the body's state and the six feet in the body frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StatePayload {
    pub state: MotionState,
    pub pose_id: u16,
    pub time_us: u64,
    pub feet_mm: [[f32; 3]; 6],
}

/// A message of version 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Message {
    Hello { nonce: u32 },
    SetPose(SetPose),
    GetState,
    Home { duration_ms: u32 },
    Halt,
    Bye,
    Welcome(WelcomePayload),
    Ack(AckStatus),
    State(StatePayload),
}

impl Message {
    /// The header's type code.
    pub fn kind(&self) -> u8 {
        match self {
            Message::Hello { .. } => kind::HELLO,
            Message::SetPose(_) => kind::SET_POSE,
            Message::GetState => kind::GET_STATE,
            Message::Home { .. } => kind::HOME,
            Message::Halt => kind::HALT,
            Message::Bye => kind::BYE,
            Message::Welcome(_) => kind::WELCOME,
            Message::Ack(_) => kind::ACK,
            Message::State(_) => kind::STATE,
        }
    }

    /// The spec's name, for logs.
    pub fn name(&self) -> &'static str {
        kind::name(self.kind())
    }
}

/// A whole datagram: the header's session and seq, and the message.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Datagram {
    pub session: u32,
    pub seq: u32,
    pub message: Message,
}

/// Why bytes are not a datagram of version 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    #[error("{len} bytes is shorter than a header and CRC ({} bytes)", HEADER_LEN + CRC_LEN)]
    TooShort { len: usize },
    #[error("wrong magic {found:02x?} (expected \"HX\")")]
    BadMagic { found: [u8; 2] },
    #[error("protocol version {found}, this side speaks {VERSION}")]
    BadVersion { found: u8 },
    #[error("{len} bytes received, but the header announces a {payload_len}-byte payload")]
    BadLength { len: usize, payload_len: u16 },
    #[error("CRC {received:08x} does not match the computed {computed:08x}")]
    BadCrc { received: u32, computed: u32 },
    #[error("unknown message type 0x{:02x}", header.kind)]
    UnknownType { header: Header },
    #[error("{} payload of {} bytes (expected {expected})", kind::name(header.kind), header.payload_len)]
    BadPayloadLength { header: Header, expected: usize },
    #[error("{} payload: {what}", kind::name(header.kind))]
    BadField { header: Header, what: &'static str },
}

impl DecodeError {
    /// The header, when it was read intact (right magic, version, length and
    /// CRC) and only the type or payload is wrong.
    pub fn header(&self) -> Option<Header> {
        match *self {
            DecodeError::UnknownType { header }
            | DecodeError::BadPayloadLength { header, .. }
            | DecodeError::BadField { header, .. } => Some(header),
            _ => None,
        }
    }

    /// A short stable name of the reason, for counters and logs.
    pub fn reason(&self) -> &'static str {
        match self {
            DecodeError::TooShort { .. } | DecodeError::BadLength { .. } => "length",
            DecodeError::BadMagic { .. } => "magic",
            DecodeError::BadVersion { .. } => "version",
            DecodeError::BadCrc { .. } => "crc",
            DecodeError::UnknownType { .. } => "type",
            DecodeError::BadPayloadLength { .. } | DecodeError::BadField { .. } => "payload",
        }
    }
}

/// Encodes a datagram into a new buffer.
pub fn encode(datagram: &Datagram) -> Vec<u8> {
    let mut out = Vec::with_capacity(MAX_DATAGRAM_LEN);
    encode_into(datagram, &mut out);
    out
}

/// Encodes a datagram, replacing the contents of `out`.
pub fn encode_into(datagram: &Datagram, out: &mut Vec<u8>) {
    out.clear();
    out.extend_from_slice(&MAGIC);
    out.push(VERSION);
    out.push(datagram.message.kind());
    out.extend_from_slice(&datagram.session.to_le_bytes());
    out.extend_from_slice(&datagram.seq.to_le_bytes());
    // The payload length is patched in once the payload is written.
    out.extend_from_slice(&[0, 0, 0, 0]);
    match &datagram.message {
        Message::Hello { nonce } => out.extend_from_slice(&nonce.to_le_bytes()),
        Message::SetPose(p) => {
            out.extend_from_slice(&p.pose_id.to_le_bytes());
            out.extend_from_slice(&[0, 0]);
            for v in [
                p.alpha_deg,
                p.beta_deg,
                p.gamma_deg,
                p.px_mm,
                p.py_mm,
                p.pz_mm,
            ] {
                out.extend_from_slice(&v.to_le_bytes());
            }
            out.extend_from_slice(&p.duration_ms.to_le_bytes());
        }
        Message::GetState | Message::Halt | Message::Bye => {}
        Message::Home { duration_ms } => out.extend_from_slice(&duration_ms.to_le_bytes()),
        Message::Welcome(w) => {
            out.extend_from_slice(&w.session.to_le_bytes());
            out.extend_from_slice(&w.nonce.to_le_bytes());
            for v in [
                w.max_tilt_deg,
                w.min_height_mm,
                w.max_height_mm,
                w.max_shift_mm,
            ] {
                out.extend_from_slice(&v.to_le_bytes());
            }
            out.extend_from_slice(&w.firmware);
        }
        Message::Ack(status) => out.extend_from_slice(&[status.code(), 0, 0, 0]),
        Message::State(s) => {
            let (state, fault) = state_codes(s.state);
            out.extend_from_slice(&[state, fault]);
            out.extend_from_slice(&s.pose_id.to_le_bytes());
            out.extend_from_slice(&s.time_us.to_le_bytes());
            for foot in &s.feet_mm {
                for v in foot {
                    out.extend_from_slice(&v.to_le_bytes());
                }
            }
        }
    }
    // Every payload of version 1 is at most 84 bytes.
    let payload_len = (out.len() - HEADER_LEN) as u16;
    out[12..14].copy_from_slice(&payload_len.to_le_bytes());
    let crc = crc32fast::hash(out);
    out.extend_from_slice(&crc.to_le_bytes());
}

/// STATE's `state` and `fault` bytes of a motion state.
fn state_codes(state: MotionState) -> (u8, u8) {
    match state {
        MotionState::Idle => (0, 0),
        MotionState::Moving => (1, 0),
        MotionState::Settled => (2, 0),
        MotionState::Halted => (3, 0),
        MotionState::Fault(code) => (4, code),
    }
}

/// Decodes one datagram. Never panics; every malformation is a [`DecodeError`].
pub fn decode(bytes: &[u8]) -> Result<Datagram, DecodeError> {
    if bytes.len() < HEADER_LEN + CRC_LEN {
        return Err(DecodeError::TooShort { len: bytes.len() });
    }
    let found = [bytes[0], bytes[1]];
    if found != MAGIC {
        return Err(DecodeError::BadMagic { found });
    }
    if bytes[2] != VERSION {
        return Err(DecodeError::BadVersion { found: bytes[2] });
    }
    let mut reader = Reader::new(&bytes[4..HEADER_LEN]);
    let session = reader.u32();
    let seq = reader.u32();
    let payload_len = reader.u16();
    let flags = reader.u16();
    if bytes.len() != HEADER_LEN + usize::from(payload_len) + CRC_LEN {
        return Err(DecodeError::BadLength {
            len: bytes.len(),
            payload_len,
        });
    }
    let (covered, crc_bytes) = bytes.split_at(bytes.len() - CRC_LEN);
    let received = Reader::new(crc_bytes).u32();
    let computed = crc32fast::hash(covered);
    if received != computed {
        return Err(DecodeError::BadCrc { received, computed });
    }
    let header = Header {
        kind: bytes[3],
        session,
        seq,
        payload_len,
        flags,
    };
    let payload = &covered[HEADER_LEN..];
    let message = decode_payload(header, payload)?;
    Ok(Datagram {
        session,
        seq,
        message,
    })
}

fn decode_payload(header: Header, payload: &[u8]) -> Result<Message, DecodeError> {
    let expected = match header.kind {
        kind::HELLO | kind::HOME | kind::ACK => 4,
        kind::SET_POSE => SET_POSE_LEN,
        kind::GET_STATE | kind::HALT | kind::BYE => 0,
        kind::WELCOME => WELCOME_LEN,
        kind::STATE => STATE_LEN,
        _ => return Err(DecodeError::UnknownType { header }),
    };
    if payload.len() != expected {
        return Err(DecodeError::BadPayloadLength { header, expected });
    }
    let mut r = Reader::new(payload);
    let message = match header.kind {
        kind::HELLO => Message::Hello { nonce: r.u32() },
        kind::SET_POSE => {
            let pose_id = r.u16();
            let _reserved = r.u16();
            Message::SetPose(SetPose {
                pose_id,
                alpha_deg: r.f32(),
                beta_deg: r.f32(),
                gamma_deg: r.f32(),
                px_mm: r.f32(),
                py_mm: r.f32(),
                pz_mm: r.f32(),
                duration_ms: r.u32(),
            })
        }
        kind::GET_STATE => Message::GetState,
        kind::HOME => Message::Home {
            duration_ms: r.u32(),
        },
        kind::HALT => Message::Halt,
        kind::BYE => Message::Bye,
        kind::WELCOME => Message::Welcome(WelcomePayload {
            session: r.u32(),
            nonce: r.u32(),
            max_tilt_deg: r.f32(),
            min_height_mm: r.f32(),
            max_height_mm: r.f32(),
            max_shift_mm: r.f32(),
            firmware: r.array::<16>(),
        }),
        kind::ACK => {
            let code = r.u8();
            let status = AckStatus::from_code(code).ok_or(DecodeError::BadField {
                header,
                what: "ACK status is not 0 to 4",
            })?;
            Message::Ack(status)
        }
        kind::STATE => {
            let state = r.u8();
            let fault = r.u8();
            let state = match (state, fault) {
                (0, _) => MotionState::Idle,
                (1, _) => MotionState::Moving,
                (2, _) => MotionState::Settled,
                (3, _) => MotionState::Halted,
                (4, 0) => {
                    return Err(DecodeError::BadField {
                        header,
                        what: "fault state with fault code 0",
                    })
                }
                (4, code) => MotionState::Fault(code),
                _ => {
                    return Err(DecodeError::BadField {
                        header,
                        what: "state is not 0 to 4",
                    })
                }
            };
            let pose_id = r.u16();
            let time_us = r.u64();
            let mut feet_mm = [[0f32; 3]; 6];
            for foot in &mut feet_mm {
                for v in foot.iter_mut() {
                    *v = r.f32();
                }
            }
            Message::State(StatePayload {
                state,
                pose_id,
                time_us,
                feet_mm,
            })
        }
        // Every other code returned UnknownType above.
        _ => return Err(DecodeError::UnknownType { header }),
    };
    Ok(message)
}

/// Little-endian reads from a slice whose length the caller has checked;
/// reading past the end yields zeros rather than panicking.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn new(bytes: &'a [u8]) -> Self {
        Self { bytes, at: 0 }
    }

    fn array<const N: usize>(&mut self) -> [u8; N] {
        let mut out = [0u8; N];
        if let Some(src) = self.bytes.get(self.at..self.at + N) {
            out.copy_from_slice(src);
        }
        self.at += N;
        out
    }

    fn u8(&mut self) -> u8 {
        self.array::<1>()[0]
    }

    fn u16(&mut self) -> u16 {
        u16::from_le_bytes(self.array())
    }

    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.array())
    }

    fn u64(&mut self) -> u64 {
        u64::from_le_bytes(self.array())
    }

    fn f32(&mut self) -> f32 {
        f32::from_le_bytes(self.array())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Compares floats by their bits, so that the round trip is exact.
    fn same(a: &Datagram, b: &Datagram) -> bool {
        encode(a) == encode(b) && format!("{a:?}") == format!("{b:?}")
    }

    fn finite_f32() -> impl Strategy<Value = f32> {
        -1.0e6f32..1.0e6f32
    }

    fn motion_state() -> impl Strategy<Value = MotionState> {
        prop_oneof![
            Just(MotionState::Idle),
            Just(MotionState::Moving),
            Just(MotionState::Settled),
            Just(MotionState::Halted),
            (1u8..=255).prop_map(MotionState::Fault),
        ]
    }

    fn ack_status() -> impl Strategy<Value = AckStatus> {
        (0u8..=4).prop_map(|c| AckStatus::from_code(c).unwrap())
    }

    fn message() -> impl Strategy<Value = Message> {
        prop_oneof![
            any::<u32>().prop_map(|nonce| Message::Hello { nonce }),
            (
                any::<u16>(),
                prop::array::uniform6(finite_f32()),
                any::<u32>()
            )
                .prop_map(|(pose_id, v, duration_ms)| Message::SetPose(SetPose {
                    pose_id,
                    alpha_deg: v[0],
                    beta_deg: v[1],
                    gamma_deg: v[2],
                    px_mm: v[3],
                    py_mm: v[4],
                    pz_mm: v[5],
                    duration_ms,
                })),
            Just(Message::GetState),
            any::<u32>().prop_map(|duration_ms| Message::Home { duration_ms }),
            Just(Message::Halt),
            Just(Message::Bye),
            (
                any::<u32>(),
                any::<u32>(),
                prop::array::uniform4(finite_f32()),
                "[a-z0-9 .-]{0,16}"
            )
                .prop_map(|(session, nonce, l, fw)| Message::Welcome(WelcomePayload {
                    session,
                    nonce,
                    max_tilt_deg: l[0],
                    min_height_mm: l[1],
                    max_height_mm: l[2],
                    max_shift_mm: l[3],
                    firmware: WelcomePayload::firmware_field(&fw),
                })),
            ack_status().prop_map(Message::Ack),
            (
                motion_state(),
                any::<u16>(),
                any::<u64>(),
                prop::array::uniform6(prop::array::uniform3(finite_f32()))
            )
                .prop_map(|(state, pose_id, time_us, feet_mm)| Message::State(
                    StatePayload {
                        state,
                        pose_id,
                        time_us,
                        feet_mm,
                    }
                )),
        ]
    }

    fn datagram() -> impl Strategy<Value = Datagram> {
        (any::<u32>(), any::<u32>(), message()).prop_map(|(session, seq, message)| Datagram {
            session,
            seq,
            message,
        })
    }

    proptest! {
        #[test]
        fn every_message_round_trips(d in datagram()) {
            let bytes = encode(&d);
            let back = decode(&bytes).expect("an encoded datagram decodes");
            prop_assert!(same(&d, &back), "{d:?} came back as {back:?}");
        }

        #[test]
        fn any_single_bit_flip_is_rejected(d in datagram(), bit in any::<prop::sample::Index>()) {
            let mut bytes = encode(&d);
            let bit = bit.index(bytes.len() * 8);
            bytes[bit / 8] ^= 1 << (bit % 8);
            prop_assert!(decode(&bytes).is_err(), "bit {bit} flipped still decodes");
        }

        #[test]
        fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..200)) {
            let _ = decode(&bytes);
        }

        /// Arbitrary bytes behind a valid header and CRC reach the payload
        /// decoders, which must not panic either.
        #[test]
        fn arbitrary_payloads_behind_a_valid_crc_never_panic(
            kind in any::<u8>(),
            payload in prop::collection::vec(any::<u8>(), 0..100),
        ) {
            let mut bytes = vec![b'H', b'X', VERSION, kind, 1, 0, 0, 0, 2, 0, 0, 0];
            bytes.extend_from_slice(&(payload.len() as u16).to_le_bytes());
            bytes.extend_from_slice(&[0, 0]);
            bytes.extend_from_slice(&payload);
            let crc = crc32fast::hash(&bytes);
            bytes.extend_from_slice(&crc.to_le_bytes());
            if let Err(e) = decode(&bytes) {
                prop_assert!(e.header().is_some(), "{e}: the header was intact");
            }
        }
    }

    #[test]
    fn crc_is_zlibs_crc32() {
        // The check value of CRC-32/ISO-HDLC (zlib's crc32).
        assert_eq!(crc32fast::hash(b"123456789"), 0xcbf4_3926);
    }

    #[test]
    fn header_layout_matches_the_spec() {
        let bytes = encode(&Datagram {
            session: 0x0403_0201,
            seq: 0x0807_0605,
            message: Message::Home { duration_ms: 1500 },
        });
        assert_eq!(&bytes[..4], &[0x48, 0x58, 1, 0x04]);
        assert_eq!(&bytes[4..8], &[1, 2, 3, 4]);
        assert_eq!(&bytes[8..12], &[5, 6, 7, 8]);
        assert_eq!(&bytes[12..16], &[4, 0, 0, 0]);
        assert_eq!(&bytes[16..20], &1500u32.to_le_bytes());
        assert_eq!(bytes.len(), 24);
        let crc = crc32fast::hash(&bytes[..20]);
        assert_eq!(&bytes[20..], &crc.to_le_bytes());
    }

    #[test]
    fn payload_sizes_match_the_spec() {
        let sizes = [
            (Message::Hello { nonce: 1 }, 4),
            (Message::GetState, 0),
            (Message::Ack(AckStatus::Accepted), 4),
        ];
        for (message, size) in sizes {
            let bytes = encode(&Datagram {
                session: 1,
                seq: 1,
                message,
            });
            assert_eq!(bytes.len(), HEADER_LEN + size + CRC_LEN, "{message:?}");
        }
        assert_eq!(SET_POSE_LEN, 2 + 2 + 6 * 4 + 4);
        assert_eq!(WELCOME_LEN, 4 + 4 + 4 * 4 + 16);
        assert_eq!(STATE_LEN, 1 + 1 + 2 + 8 + 18 * 4);
    }

    /// Re-encodes `bytes` with a correct CRC, so that a test reaches the
    /// check after it.
    fn fix_crc(bytes: &mut Vec<u8>) {
        let n = bytes.len() - CRC_LEN;
        bytes.truncate(n);
        let crc = crc32fast::hash(bytes);
        bytes.extend_from_slice(&crc.to_le_bytes());
    }

    #[test]
    fn each_malformation_has_its_own_error() {
        let good = encode(&Datagram {
            session: 7,
            seq: 9,
            message: Message::Ack(AckStatus::Accepted),
        });
        assert!(matches!(
            decode(&good[..10]),
            Err(DecodeError::TooShort { len: 10 })
        ));
        let mut b = good.clone();
        b[0] = b'X';
        assert!(matches!(decode(&b), Err(DecodeError::BadMagic { .. })));
        let mut b = good.clone();
        b[2] = 2;
        assert!(matches!(
            decode(&b),
            Err(DecodeError::BadVersion { found: 2 })
        ));
        let mut b = good.clone();
        b.push(0);
        assert!(matches!(decode(&b), Err(DecodeError::BadLength { .. })));
        let mut b = good.clone();
        b[16] = 1;
        assert!(matches!(decode(&b), Err(DecodeError::BadCrc { .. })));
        let mut b = good.clone();
        b[3] = 0x42;
        fix_crc(&mut b);
        assert!(matches!(decode(&b), Err(DecodeError::UnknownType { .. })));
        let mut b = good.clone();
        b[16] = 9;
        fix_crc(&mut b);
        let e = decode(&b).unwrap_err();
        assert!(matches!(e, DecodeError::BadField { .. }), "{e}");
        assert_eq!(e.header().map(|h| (h.session, h.seq)), Some((7, 9)));
        // A GET_STATE with a 4-byte payload: length and CRC right, payload wrong.
        let mut b = good.clone();
        b[3] = kind::GET_STATE;
        fix_crc(&mut b);
        assert!(matches!(
            decode(&b),
            Err(DecodeError::BadPayloadLength { expected: 0, .. })
        ));
    }

    #[test]
    fn fault_state_needs_a_fault_code() {
        let mut b = encode(&Datagram {
            session: 1,
            seq: 1,
            message: Message::State(StatePayload {
                state: MotionState::Fault(3),
                pose_id: 0,
                time_us: 0,
                feet_mm: [[0.0; 3]; 6],
            }),
        });
        b[17] = 0;
        fix_crc(&mut b);
        assert!(matches!(decode(&b), Err(DecodeError::BadField { .. })));
    }

    #[test]
    fn firmware_is_cut_at_a_character_boundary() {
        let field = WelcomePayload::firmware_field("groundcal-sim-ßßßß");
        let w = WelcomePayload {
            session: 1,
            nonce: 1,
            max_tilt_deg: 0.0,
            min_height_mm: 0.0,
            max_height_mm: 0.0,
            max_shift_mm: 0.0,
            firmware: field,
        };
        assert_eq!(w.firmware_text(), "groundcal-sim-ß");
    }
}
