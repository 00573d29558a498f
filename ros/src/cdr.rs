//! CDR, the encoding of ROS 2 messages (OMG XCDR version 1, plain): a
//! 4-byte encapsulation header, then the fields in order, each primitive
//! aligned to its own size (at most 8) counted from the end of the header.
//! Strings are a `u32` length that counts a closing NUL, the bytes and the
//! NUL; sequences a `u32` count and the elements; fixed arrays the elements
//! alone.
//!
//! The writer writes little-endian (`CDR_LE`, what every robot's computer
//! writes). The reader reads both byte orders, and every read is checked:
//! a message cut short or a length beyond the bytes left is an error that
//! says where, never a panic or a huge allocation.

/// The encapsulation header of little-endian plain CDR.
pub const CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];
/// The encapsulation header of big-endian plain CDR.
pub const CDR_BE: [u8; 4] = [0x00, 0x00, 0x00, 0x00];

/// Encodes one message.
#[derive(Debug, Clone)]
pub struct CdrWriter {
    bytes: Vec<u8>,
}

impl Default for CdrWriter {
    fn default() -> Self {
        Self::new()
    }
}

impl CdrWriter {
    pub fn new() -> Self {
        Self::with_capacity(64)
    }

    /// A writer with room for `capacity` bytes of payload (an image's pixels
    /// are copied once, not regrown into).
    pub fn with_capacity(capacity: usize) -> Self {
        let mut bytes = Vec::with_capacity(capacity + CDR_LE.len());
        bytes.extend_from_slice(&CDR_LE);
        Self { bytes }
    }

    /// A writer that encodes into `buffer`, emptied first: its memory is
    /// reused from message to message (a session writes a few hundred
    /// images of 600 kB each).
    pub fn reusing(mut buffer: Vec<u8>) -> Self {
        buffer.clear();
        buffer.extend_from_slice(&CDR_LE);
        Self { bytes: buffer }
    }

    /// The encoded message, header included.
    pub fn finish(self) -> Vec<u8> {
        self.bytes
    }

    fn align(&mut self, size: usize) {
        let position = self.bytes.len() - CDR_LE.len();
        let padding = (size - position % size) % size;
        self.bytes.resize(self.bytes.len() + padding, 0);
    }

    pub fn u8(&mut self, value: u8) {
        self.bytes.push(value);
    }

    pub fn bool(&mut self, value: bool) {
        self.bytes.push(u8::from(value));
    }

    pub fn u32(&mut self, value: u32) {
        self.align(4);
        self.bytes.extend_from_slice(&value.to_le_bytes());
    }

    pub fn i32(&mut self, value: i32) {
        self.align(4);
        self.bytes.extend_from_slice(&value.to_le_bytes());
    }

    pub fn f32(&mut self, value: f32) {
        self.align(4);
        self.bytes.extend_from_slice(&value.to_le_bytes());
    }

    pub fn f64(&mut self, value: f64) {
        self.align(8);
        self.bytes.extend_from_slice(&value.to_le_bytes());
    }

    /// A length or a count. Messages here never hold 4 GiB; a longer one is
    /// a bug of the caller.
    pub fn length(&mut self, length: usize) {
        self.u32(u32::try_from(length).expect("a CDR sequence holds fewer than 2³² elements"));
    }

    pub fn string(&mut self, value: &str) {
        self.length(value.len() + 1);
        self.bytes.extend_from_slice(value.as_bytes());
        self.bytes.push(0);
    }

    /// A `uint8[]` (an image's or a cloud's data).
    pub fn byte_sequence(&mut self, value: &[u8]) {
        self.length(value.len());
        self.bytes.extend_from_slice(value);
    }

    /// A `uint8[]` holding `values` as little-endian 16-bit words (an
    /// image's pixels, written from them without a copy in between).
    pub fn u16_le_byte_sequence(&mut self, values: impl ExactSizeIterator<Item = u16>) {
        self.length(2 * values.len());
        let start = self.bytes.len();
        self.bytes.resize(start + 2 * values.len(), 0);
        for (bytes, value) in self.bytes[start..].chunks_exact_mut(2).zip(values) {
            bytes.copy_from_slice(&value.to_le_bytes());
        }
    }

    /// A `float64[]`.
    pub fn f64_sequence(&mut self, values: &[f64]) {
        self.length(values.len());
        self.f64_array(values);
    }

    /// A `float64[N]`: the elements alone.
    pub fn f64_array(&mut self, values: &[f64]) {
        for &value in values {
            self.f64(value);
        }
    }
}

/// Why a message could not be decoded, and where (bytes from the start of
/// the message, its header included).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("CDR message, byte {offset}: {what}")]
pub struct CdrError {
    pub offset: usize,
    pub what: String,
}

/// Decodes one message.
#[derive(Debug, Clone)]
pub struct CdrReader<'a> {
    bytes: &'a [u8],
    position: usize,
    little_endian: bool,
}

impl<'a> CdrReader<'a> {
    /// Reads the encapsulation header: plain CDR of either byte order.
    pub fn new(bytes: &'a [u8]) -> Result<Self, CdrError> {
        let header = bytes.get(..4).ok_or_else(|| CdrError {
            offset: 0,
            what: format!(
                "{} bytes: shorter than the 4-byte encapsulation header",
                bytes.len()
            ),
        })?;
        let little_endian = match [header[0], header[1]] {
            [0x00, 0x01] => true,
            [0x00, 0x00] => false,
            kind => {
                return Err(CdrError {
                    offset: 0,
                    what: format!(
                        "encapsulation {:02x}{:02x}: only plain CDR (0000 or 0001) is read",
                        kind[0], kind[1]
                    ),
                })
            }
        };
        Ok(Self {
            bytes,
            position: 4,
            little_endian,
        })
    }

    fn error(&self, what: impl Into<String>) -> CdrError {
        CdrError {
            offset: self.position,
            what: what.into(),
        }
    }

    /// Bytes not read yet.
    pub fn remaining(&self) -> usize {
        self.bytes.len() - self.position
    }

    fn align(&mut self, size: usize) -> Result<(), CdrError> {
        let position = self.position - 4;
        let padding = (size - position % size) % size;
        if padding > self.remaining() {
            return Err(self.error("the message ends inside an alignment gap"));
        }
        self.position += padding;
        Ok(())
    }

    fn take<const N: usize>(&mut self, what: &str) -> Result<[u8; N], CdrError> {
        self.align(N.min(8))?;
        let slice = self
            .bytes
            .get(self.position..self.position + N)
            .ok_or_else(|| self.error(format!("the message ends inside {what}")))?;
        let mut value: [u8; N] = slice.try_into().expect("N bytes");
        if !self.little_endian {
            value.reverse();
        }
        self.position += N;
        Ok(value)
    }

    pub fn u8(&mut self, what: &str) -> Result<u8, CdrError> {
        Ok(self.take::<1>(what)?[0])
    }

    pub fn bool(&mut self, what: &str) -> Result<bool, CdrError> {
        match self.u8(what)? {
            0 => Ok(false),
            1 => Ok(true),
            other => {
                self.position -= 1;
                Err(self.error(format!("{what}: {other} is not a boolean (0 or 1)")))
            }
        }
    }

    pub fn u32(&mut self, what: &str) -> Result<u32, CdrError> {
        Ok(u32::from_le_bytes(self.take::<4>(what)?))
    }

    pub fn i32(&mut self, what: &str) -> Result<i32, CdrError> {
        Ok(i32::from_le_bytes(self.take::<4>(what)?))
    }

    pub fn f32(&mut self, what: &str) -> Result<f32, CdrError> {
        Ok(f32::from_le_bytes(self.take::<4>(what)?))
    }

    pub fn f64(&mut self, what: &str) -> Result<f64, CdrError> {
        Ok(f64::from_le_bytes(self.take::<8>(what)?))
    }

    /// A sequence's count, checked against the bytes left at `element_size`
    /// bytes at least per element (so that no count allocates more than the
    /// message holds).
    pub fn length(&mut self, what: &str, element_size: usize) -> Result<usize, CdrError> {
        let count = self.u32(what)? as usize;
        if count.saturating_mul(element_size.max(1)) > self.remaining() {
            self.position -= 4;
            return Err(self.error(format!(
                "{what}: {count} elements, more than the {} bytes left hold",
                self.remaining() - 4
            )));
        }
        Ok(count)
    }

    pub fn string(&mut self, what: &str) -> Result<String, CdrError> {
        let length = self.length(what, 1)?;
        let start = self.position;
        let bytes = &self.bytes[start..start + length];
        let text = match bytes.split_last() {
            // Some writers leave out the NUL of an empty string.
            None => "",
            Some((0, text)) => std::str::from_utf8(text)
                .map_err(|e| self.error(format!("{what}: not UTF-8 ({e})")))?,
            Some(_) => return Err(self.error(format!("{what}: the string has no closing NUL"))),
        };
        self.position += length;
        Ok(text.to_owned())
    }

    /// A `uint8[]`, borrowed.
    pub fn byte_sequence(&mut self, what: &str) -> Result<&'a [u8], CdrError> {
        let length = self.length(what, 1)?;
        let start = self.position;
        self.position += length;
        Ok(&self.bytes[start..start + length])
    }

    pub fn f64_sequence(&mut self, what: &str) -> Result<Vec<f64>, CdrError> {
        let count = self.length(what, 8)?;
        (0..count).map(|_| self.f64(what)).collect()
    }

    pub fn f64_array<const N: usize>(&mut self, what: &str) -> Result<[f64; N], CdrError> {
        let mut values = [0.0; N];
        for value in &mut values {
            *value = self.f64(what)?;
        }
        Ok(values)
    }

    /// Whether the bytes are little-endian (a `uint8[]` of 16-bit pixels is
    /// the image's own byte order, not the message's).
    pub fn little_endian(&self) -> bool {
        self.little_endian
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn primitives_are_aligned_from_the_end_of_the_header() {
        let mut w = CdrWriter::new();
        w.u8(7);
        w.f64(1.5);
        w.string("ab");
        w.u32(9);
        let bytes = w.finish();
        // header, u8, 7 bytes of padding, f64, "ab" as 3+NUL, u32 aligned.
        assert_eq!(&bytes[..4], &CDR_LE);
        assert_eq!(bytes[4], 7);
        assert_eq!(&bytes[5..12], &[0; 7]);
        assert_eq!(&bytes[12..20], &1.5f64.to_le_bytes());
        assert_eq!(&bytes[20..24], &3u32.to_le_bytes());
        assert_eq!(&bytes[24..27], b"ab\0");
        assert_eq!(bytes[27], 0, "padding to 4");
        assert_eq!(&bytes[28..32], &9u32.to_le_bytes());
        let mut r = CdrReader::new(&bytes).unwrap();
        assert_eq!(r.u8("a").unwrap(), 7);
        assert_eq!(r.f64("b").unwrap(), 1.5);
        assert_eq!(r.string("c").unwrap(), "ab");
        assert_eq!(r.u32("d").unwrap(), 9);
        assert_eq!(r.remaining(), 0);
    }

    #[test]
    fn big_endian_messages_are_read() {
        // The count, 4 bytes of padding, then the f64 at 8 from the header.
        let bytes = [
            0, 0, 0, 0, 0, 0, 0, 2, 0, 0, 0, 0, 0x3f, 0xf8, 0, 0, 0, 0, 0, 0,
        ];
        let mut r = CdrReader::new(&bytes).unwrap();
        assert_eq!(r.u32("count").unwrap(), 2);
        assert_eq!(r.f64("value").unwrap(), 1.5);
    }

    #[test]
    fn a_count_beyond_the_message_is_an_error_that_says_where() {
        let mut w = CdrWriter::new();
        w.u32(1_000_000);
        let bytes = w.finish();
        let e = CdrReader::new(&bytes)
            .unwrap()
            .byte_sequence("data")
            .unwrap_err();
        assert_eq!(e.offset, 4);
        assert!(e.what.contains("data: 1000000 elements"), "{e}");
        let e = CdrReader::new(&[0, 1]).unwrap_err();
        assert!(e.what.contains("shorter than"), "{e}");
        let e = CdrReader::new(&[0, 7, 0, 0]).unwrap_err();
        assert!(e.what.contains("only plain CDR"), "{e}");
    }

    #[test]
    fn a_string_without_its_nul_or_not_utf8_is_refused() {
        let bytes = [0, 1, 0, 0, 2, 0, 0, 0, b'a', b'b'];
        let e = CdrReader::new(&bytes)
            .unwrap()
            .string("frame_id")
            .unwrap_err();
        assert!(e.what.contains("no closing NUL"), "{e}");
        let bytes = [0, 1, 0, 0, 2, 0, 0, 0, 0xff, 0];
        let e = CdrReader::new(&bytes)
            .unwrap()
            .string("frame_id")
            .unwrap_err();
        assert!(e.what.contains("not UTF-8"), "{e}");
    }
}
