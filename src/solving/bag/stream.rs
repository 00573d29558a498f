//! The messages of an MCAP file, read as a stream: record by record from any
//! `Read`, chunks decompressed one at a time (zstd or lz4, as rosbag2 writes
//! them, or none), so that a bag of gigabytes takes the memory of one chunk.
//! The summary at the end is not needed and not read.
//!
//! The four records a reader needs (Schema, Channel, Message, Chunk) are
//! parsed here with every length checked against the record's own bytes:
//! the `mcap` crate's parser reserves a string's declared length before
//! reading it, so a record claiming a 4 GB topic name costs 4 GB (found by
//! fuzzing, `fuzz/README.md`).
//!
//! Every length is checked before anything is allocated for it: a record or
//! a chunk larger than [`Limits`] allow, a chunk that decompresses to another
//! size or CRC than its header says, a message on a channel never declared
//! are errors that give the byte offset, never a panic.

use std::collections::HashMap;
use std::io::Read;

/// MCAP's magic, at both ends of a file.
pub const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// How large one record and one decompressed chunk may be.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    pub record_bytes: u64,
    pub chunk_bytes: u64,
}

impl Default for Limits {
    /// 32 MiB each, what a real rosbag2 writes with room to spare: its MCAP
    /// plugin closes a chunk at 768 KiB by default (one message larger than
    /// that is a chunk of its own), and the largest depth image of a camera
    /// in use is a few MB (640 × 480 at 32FC1 is 1.2 MB, 1280 × 720 is
    /// 3.7 MB). A reader that took what a hostile file claims (a zstd chunk
    /// of 512 MiB made of 16 kB) would need a robot computer's whole memory:
    /// with these, any input peaks under 256 MB (docs/reliability.md).
    fn default() -> Self {
        Self {
            record_bytes: 32 << 20,
            chunk_bytes: 32 << 20,
        }
    }
}

/// One message, borrowed from the record or chunk it was read from.
#[derive(Debug, Clone, Copy)]
pub struct StreamMessage<'a> {
    pub topic: &'a str,
    /// The schema's name (`sensor_msgs/msg/Image`), "" for none.
    pub schema: &'a str,
    /// The message encoding (`cdr` for ROS 2).
    pub encoding: &'a str,
    /// Nanoseconds, as the file gives them.
    pub log_time: u64,
    pub data: &'a [u8],
    /// The chunk it came in (counted from 0 in file order), if any.
    pub chunk: Option<u64>,
}

/// Why the file could not be read, and where (bytes from its start; for a
/// record inside a chunk, the chunk's offset).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("byte {offset}: {what}")]
pub struct StreamError {
    pub offset: u64,
    pub what: String,
}

/// What a pass over the file saw.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StreamCounts {
    pub messages: u64,
    pub chunks: u64,
}

#[derive(Debug, Clone)]
struct ChannelInfo {
    topic: String,
    schema_id: u16,
    encoding: String,
}

/// The schemas and channels declared so far.
#[derive(Debug, Clone, Default)]
struct Declarations {
    schemas: HashMap<u16, String>,
    channels: HashMap<u16, ChannelInfo>,
}

/// Reads the messages of MCAP files; the schemas and channels it has seen
/// are kept from one pass over a file to the next, so that a second pass
/// can skip chunks (and the declarations in them) it does not need.
#[derive(Debug, Clone, Default)]
pub struct McapStream {
    limits: Limits,
    declared: Declarations,
    /// The attachments kept ([`McapStream::keep_attachments`]): name, data.
    attachments: Vec<(String, Vec<u8>)>,
    attachments_named: Option<String>,
}

impl McapStream {
    pub fn new(limits: Limits) -> Self {
        Self {
            limits,
            declared: Declarations::default(),
            attachments: Vec::new(),
            attachments_named: None,
        }
    }

    /// Keeps, from the passes that follow, the attachments whose names
    /// start with `prefix` (each within the reader's record limit).
    pub fn keep_attachments(&mut self, prefix: &str) {
        self.attachments_named = Some(prefix.to_string());
    }

    /// The attachments kept so far, in file order.
    pub fn take_attachments(&mut self) -> Vec<(String, Vec<u8>)> {
        std::mem::take(&mut self.attachments)
    }

    /// Reads every message from `source`, in file order, and hands those
    /// whose topic `wanted` accepts to `each` (which may stop the pass with
    /// its own error). Chunks `skip_chunk` names (by their ordinal) are read
    /// past without being decompressed.
    pub fn read<R: Read, E>(
        &mut self,
        mut source: R,
        wanted: impl Fn(&str) -> bool,
        skip_chunk: impl Fn(u64) -> bool,
        mut each: impl FnMut(StreamMessage<'_>) -> Result<(), E>,
    ) -> Result<StreamCounts, ReadError<E>> {
        let limits = self.limits;
        let mut magic = [0u8; 8];
        read_exact(&mut source, &mut magic, 0, "the file's magic")?;
        if &magic != MAGIC {
            return Err(stream_error(
                0,
                "not an MCAP file (its first 8 bytes are not MCAP's magic)",
            ));
        }
        let mut offset = 8u64;
        let mut counts = StreamCounts::default();
        let mut body = Vec::new();
        let mut chunk = Vec::new();
        loop {
            let mut opcode_and_length = [0u8; 9];
            // The end: a file cut after a whole record still gives its
            // messages (a bag whose recorder was killed has no summary).
            let got = read_up_to(&mut source, &mut opcode_and_length, offset)?;
            if got == 0 {
                return Ok(counts);
            }
            if got < 9 {
                return Err(stream_error(
                    offset,
                    "the file ends inside a record's header",
                ));
            }
            let opcode = opcode_and_length[0];
            let mut length_bytes = [0u8; 8];
            length_bytes.copy_from_slice(&opcode_and_length[1..]);
            let length = u64::from_le_bytes(length_bytes);
            if length > limits.record_bytes {
                return Err(stream_error(
                    offset,
                    format!(
                        "a record of {length} bytes (opcode 0x{opcode:02x}): more than the {} this reader takes",
                        limits.record_bytes
                    ),
                ));
            }
            let record_offset = offset;
            // Grown as the bytes come: a length that claims more than the
            // file holds costs no memory.
            body.clear();
            match (&mut source).take(length).read_to_end(&mut body) {
                Ok(got) if got as u64 == length => {}
                Ok(got) => {
                    return Err(stream_error(
                        offset + 9,
                        format!("the file ends inside a record ({got} of {length} bytes)"),
                    ))
                }
                Err(e) => return Err(stream_error(offset + 9, format!("cannot read: {e}"))),
            }
            offset += 9 + length;
            if opcode == op::CHUNK {
                let ordinal = counts.chunks;
                counts.chunks += 1;
                if skip_chunk(ordinal) {
                    continue;
                }
            }
            let record = parse(opcode, &body).map_err(|what| {
                stream_error(record_offset, format!("record 0x{opcode:02x}: {what}"))
            })?;
            let mut context = Dispatch {
                declared: &mut self.declared,
                wanted: &wanted,
                each: &mut each,
                counts: &mut counts,
                offset: record_offset,
                chunk: None,
            };
            match record {
                Parsed::Attachment { name, data } => {
                    if self
                        .attachments_named
                        .as_deref()
                        .is_some_and(|prefix| name.starts_with(prefix))
                    {
                        let kept: usize = self.attachments.iter().map(|(_, d)| d.len()).sum();
                        if (kept + data.len()) as u64 > limits.record_bytes {
                            return Err(stream_error(
                                record_offset,
                                format!(
                                    "the attachments kept reach more than the {} bytes this reader takes",
                                    limits.record_bytes
                                ),
                            ));
                        }
                        self.attachments.push((name, data.to_vec()));
                    }
                }
                Parsed::Chunk(header, data) => {
                    decompress(&header, data, limits, &mut chunk)
                        .map_err(|what| stream_error(record_offset, what))?;
                    context.chunk = Some(context.counts.chunks - 1);
                    let mut inner = chunk.as_slice();
                    while !inner.is_empty() {
                        let (opcode, body, rest) = split_record(inner).map_err(|what| {
                            stream_error(record_offset, format!("a record in the chunk: {what}"))
                        })?;
                        inner = rest;
                        let record = parse(opcode, body).map_err(|what| {
                            stream_error(
                                record_offset,
                                format!("a record 0x{opcode:02x} in the chunk: {what}"),
                            )
                        })?;
                        if matches!(record, Parsed::Chunk(..)) {
                            return Err(stream_error(record_offset, "a chunk inside a chunk"));
                        }
                        context.dispatch(record)?;
                    }
                }
                Parsed::DataEnd => return Ok(counts),
                other => context.dispatch(other)?,
            }
        }
    }
}

/// The records a reader of messages needs; the others are passed over.
enum Parsed<'a> {
    Schema {
        id: u16,
        name: String,
    },
    Channel {
        id: u16,
        info: ChannelInfo,
    },
    Message {
        channel: u16,
        log_time: u64,
        data: &'a [u8],
    },
    Chunk(ChunkHeader, &'a [u8]),
    Attachment {
        name: String,
        data: &'a [u8],
    },
    DataEnd,
    Other,
}

/// What a chunk's header says of its records.
struct ChunkHeader {
    uncompressed_size: u64,
    uncompressed_crc: u32,
    compression: String,
}

/// MCAP's opcodes (the specification's table).
mod op {
    pub const SCHEMA: u8 = 0x03;
    pub const CHANNEL: u8 = 0x04;
    pub const MESSAGE: u8 = 0x05;
    pub const CHUNK: u8 = 0x06;
    pub const ATTACHMENT: u8 = 0x09;
    pub const DATA_END: u8 = 0x0F;
}

/// A record's fields, read in order, each checked against what is left.
struct Fields<'a> {
    bytes: &'a [u8],
}

impl<'a> Fields<'a> {
    fn take(&mut self, count: u64, what: &str) -> Result<&'a [u8], String> {
        if count > self.bytes.len() as u64 {
            return Err(format!(
                "{what} of {count} bytes, where the record has {} left",
                self.bytes.len()
            ));
        }
        let (taken, rest) = self.bytes.split_at(count as usize);
        self.bytes = rest;
        Ok(taken)
    }

    fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N], String> {
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(N as u64, what)?);
        Ok(out)
    }

    fn u16(&mut self, what: &str) -> Result<u16, String> {
        self.array(what).map(u16::from_le_bytes)
    }

    fn u32(&mut self, what: &str) -> Result<u32, String> {
        self.array(what).map(u32::from_le_bytes)
    }

    fn u64(&mut self, what: &str) -> Result<u64, String> {
        self.array(what).map(u64::from_le_bytes)
    }

    fn string(&mut self, what: &str) -> Result<String, String> {
        let length = self.u32(what)?;
        let bytes = self.take(u64::from(length), what)?;
        String::from_utf8(bytes.to_vec()).map_err(|_| format!("{what} is not UTF-8"))
    }
}

fn parse(opcode: u8, body: &[u8]) -> Result<Parsed<'_>, String> {
    let mut f = Fields { bytes: body };
    Ok(match opcode {
        op::SCHEMA => Parsed::Schema {
            id: f.u16("the schema's id")?,
            name: f.string("the schema's name")?,
        },
        op::CHANNEL => Parsed::Channel {
            id: f.u16("the channel's id")?,
            info: ChannelInfo {
                schema_id: f.u16("the channel's schema id")?,
                topic: f.string("the channel's topic")?,
                encoding: f.string("the channel's message encoding")?,
            },
        },
        op::MESSAGE => {
            let channel = f.u16("the message's channel")?;
            f.u32("the message's sequence")?;
            let log_time = f.u64("the message's log time")?;
            f.u64("the message's publish time")?;
            Parsed::Message {
                channel,
                log_time,
                data: f.bytes,
            }
        }
        op::CHUNK => {
            f.u64("the chunk's first message time")?;
            f.u64("the chunk's last message time")?;
            let uncompressed_size = f.u64("the chunk's uncompressed size")?;
            let uncompressed_crc = f.u32("the chunk's CRC")?;
            let compression = f.string("the chunk's compression")?;
            let length = f.u64("the chunk's records")?;
            let data = f.take(length, "the chunk's records")?;
            Parsed::Chunk(
                ChunkHeader {
                    uncompressed_size,
                    uncompressed_crc,
                    compression,
                },
                data,
            )
        }
        op::ATTACHMENT => {
            f.u64("the attachment's log time")?;
            f.u64("the attachment's create time")?;
            let name = f.string("the attachment's name")?;
            f.string("the attachment's media type")?;
            let length = f.u64("the attachment's data")?;
            let data = f.take(length, "the attachment's data")?;
            let crc = f.u32("the attachment's CRC")?;
            // The CRC covers every field before it.
            let covered = &body[..body.len() - f.bytes.len() - 4];
            if crc != 0 && crc32fast::hash(covered) != crc {
                return Err(format!("the attachment \"{name}\" does not match its CRC"));
            }
            Parsed::Attachment { name, data }
        }
        op::DATA_END => Parsed::DataEnd,
        _ => Parsed::Other,
    })
}

/// The first record of `bytes` (inside a chunk): its opcode, its body and
/// what follows it.
fn split_record(bytes: &[u8]) -> Result<(u8, &[u8], &[u8]), String> {
    let mut f = Fields { bytes };
    let [opcode] = f.array::<1>("an opcode")?;
    let length = f.u64("a record's length")?;
    let body = f.take(length, "a record")?;
    Ok((opcode, body, f.bytes))
}

/// [`McapStream::read`] of one file, from the start, every chunk read.
pub fn for_each_message<R: Read, E>(
    source: R,
    limits: Limits,
    wanted: impl Fn(&str) -> bool,
    each: impl FnMut(StreamMessage<'_>) -> Result<(), E>,
) -> Result<StreamCounts, ReadError<E>> {
    McapStream::new(limits).read(source, wanted, |_| false, each)
}

/// A stream's error, or the one `each` stopped it with.
#[derive(Debug)]
pub enum ReadError<E> {
    Stream(StreamError),
    Stopped(E),
}

fn stream_error<E>(offset: u64, what: impl Into<String>) -> ReadError<E> {
    ReadError::Stream(StreamError {
        offset,
        what: what.into(),
    })
}

/// Where a record goes: declarations are kept, messages handed on.
struct Dispatch<'a, W, F> {
    declared: &'a mut Declarations,
    wanted: &'a W,
    each: &'a mut F,
    counts: &'a mut StreamCounts,
    offset: u64,
    chunk: Option<u64>,
}

impl<W: Fn(&str) -> bool, F> Dispatch<'_, W, F> {
    fn dispatch<E>(&mut self, record: Parsed<'_>) -> Result<(), ReadError<E>>
    where
        F: FnMut(StreamMessage<'_>) -> Result<(), E>,
    {
        match record {
            Parsed::Schema { id, name } => {
                self.declared.schemas.insert(id, name);
            }
            Parsed::Channel { id, info } => {
                self.declared.channels.insert(id, info);
            }
            Parsed::Message {
                channel: channel_id,
                log_time,
                data,
            } => {
                let Some(channel) = self.declared.channels.get(&channel_id) else {
                    return Err(stream_error(
                        self.offset,
                        format!(
                            "a message on channel {channel_id}, which no Channel record declared before it"
                        ),
                    ));
                };
                if !(self.wanted)(&channel.topic) {
                    return Ok(());
                }
                self.counts.messages += 1;
                let schema = self
                    .declared
                    .schemas
                    .get(&channel.schema_id)
                    .map_or("", String::as_str);
                (self.each)(StreamMessage {
                    topic: &channel.topic,
                    schema,
                    encoding: &channel.encoding,
                    log_time,
                    data,
                    chunk: self.chunk,
                })
                .map_err(ReadError::Stopped)?;
            }
            Parsed::Chunk(..) | Parsed::Attachment { .. } | Parsed::DataEnd | Parsed::Other => {}
        }
        Ok(())
    }
}

/// A chunk's records into `out`, checked against its header's size and CRC.
fn decompress(
    header: &ChunkHeader,
    data: &[u8],
    limits: Limits,
    out: &mut Vec<u8>,
) -> Result<(), String> {
    if header.uncompressed_size > limits.chunk_bytes {
        return Err(format!(
            "a chunk of {} bytes uncompressed: more than the {} this reader takes",
            header.uncompressed_size, limits.chunk_bytes
        ));
    }
    let size = header.uncompressed_size as usize;
    out.clear();
    // Reserved once, at the size allowed above: read_to_end would otherwise
    // double its buffer past it, and hold both while it copies.
    out.reserve_exact(size + 1);
    let read = |reader: &mut dyn Read, out: &mut Vec<u8>| -> Result<(), String> {
        // One byte more than the header says, to catch a longer chunk.
        reader
            .take(size as u64 + 1)
            .read_to_end(out)
            .map(|_| ())
            .map_err(|e| format!("{} chunk: {e}", header.compression))
    };
    match header.compression.as_str() {
        "" => out.extend_from_slice(data),
        "zstd" => {
            let mut decoder = ruzstd::decoding::StreamingDecoder::new(data)
                .map_err(|e| format!("zstd chunk: {e}"))?;
            read(&mut decoder, out)?;
        }
        "lz4" => read(&mut lz4_flex::frame::FrameDecoder::new(data), out)?,
        other => {
            return Err(format!(
                "a chunk compressed with \"{other}\": this reader knows zstd, lz4 and none"
            ))
        }
    }
    if out.len() != size {
        return Err(format!(
            "a chunk that decompresses to {} bytes where its header says {size}",
            out.len()
        ));
    }
    // 0: no CRC was written (MCAP's rule).
    if header.uncompressed_crc != 0 && crc32fast::hash(out) != header.uncompressed_crc {
        return Err("a chunk whose CRC does not match its records: the file is corrupt".into());
    }
    Ok(())
}

fn read_exact<R: Read, E>(
    source: &mut R,
    buffer: &mut [u8],
    offset: u64,
    what: &str,
) -> Result<(), ReadError<E>> {
    let got = read_up_to(source, buffer, offset)?;
    if got < buffer.len() {
        return Err(stream_error(
            offset,
            format!(
                "the file ends inside {what} ({got} of {} bytes)",
                buffer.len()
            ),
        ));
    }
    Ok(())
}

/// Reads until `buffer` is full or the file ends; how many bytes came.
fn read_up_to<R: Read, E>(
    source: &mut R,
    buffer: &mut [u8],
    offset: u64,
) -> Result<usize, ReadError<E>> {
    let mut got = 0;
    while got < buffer.len() {
        match source.read(&mut buffer[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => {
                return Err(stream_error(
                    offset + got as u64,
                    format!("cannot read: {e}"),
                ))
            }
        }
    }
    Ok(got)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A record as MCAP frames it: opcode, length, body.
    fn record(opcode: u8, body: &[u8]) -> Vec<u8> {
        let mut bytes = vec![opcode];
        bytes.extend_from_slice(&(body.len() as u64).to_le_bytes());
        bytes.extend_from_slice(body);
        bytes
    }

    /// A message as the tests compare them: topic, schema, log time, data.
    type Seen = (String, String, u64, Vec<u8>);

    fn messages(file: &[u8]) -> Result<Vec<Seen>, StreamError> {
        let mut seen = Vec::new();
        for_each_message(
            file,
            Limits::default(),
            |_| true,
            |m| -> Result<(), ()> {
                seen.push((m.topic.into(), m.schema.into(), m.log_time, m.data.to_vec()));
                Ok(())
            },
        )
        .map_err(|e| match e {
            ReadError::Stream(e) => e,
            ReadError::Stopped(()) => unreachable!(),
        })?;
        Ok(seen)
    }

    /// An attachment record: times, name, media type, data, CRC (0: none).
    fn attachment(name: &str, data: &[u8], crc: Option<u32>) -> Vec<u8> {
        let mut body = Vec::new();
        body.extend_from_slice(&1u64.to_le_bytes());
        body.extend_from_slice(&2u64.to_le_bytes());
        for text in [name, "text/plain"] {
            body.extend_from_slice(&(text.len() as u32).to_le_bytes());
            body.extend_from_slice(text.as_bytes());
        }
        body.extend_from_slice(&(data.len() as u64).to_le_bytes());
        body.extend_from_slice(data);
        let crc = crc.unwrap_or_else(|| crc32fast::hash(&body));
        body.extend_from_slice(&crc.to_le_bytes());
        record(op::ATTACHMENT, &body)
    }

    /// The attachments a pass keeps: those named with the prefix, checked
    /// against their CRC (a wrong one is named), within the record limit.
    #[test]
    fn attachments_are_kept_by_name_and_checked() {
        let file = |records: &[Vec<u8>]| {
            let mut bytes = MAGIC.to_vec();
            for r in records {
                bytes.extend_from_slice(r);
            }
            bytes.extend_from_slice(&record(op::DATA_END, &[0; 4]));
            bytes
        };
        let read = |bytes: &[u8], limits: Limits| {
            let mut stream = McapStream::new(limits);
            stream.keep_attachments("groundcal/");
            stream
                .read(bytes, |_| true, |_| false, |_| Ok::<(), ()>(()))
                .map(|_| stream.take_attachments())
        };
        let good = file(&[
            attachment("result.json", b"{}", None),
            attachment("groundcal/a.txt", b"first", None),
            attachment("groundcal/b.txt", b"second", Some(0)),
        ]);
        let kept = read(&good, Limits::default()).unwrap();
        assert_eq!(
            kept,
            [
                ("groundcal/a.txt".to_string(), b"first".to_vec()),
                ("groundcal/b.txt".to_string(), b"second".to_vec())
            ]
        );
        let bad = file(&[attachment("groundcal/a.txt", b"first", Some(7))]);
        match read(&bad, Limits::default()) {
            Err(ReadError::Stream(e)) => assert!(
                e.to_string()
                    .contains("\"groundcal/a.txt\" does not match its CRC"),
                "{e}"
            ),
            other => panic!("{other:?}"),
        }
        let small = Limits {
            record_bytes: 130,
            ..Limits::default()
        };
        let many = file(&[
            attachment("groundcal/a", &[1; 70], None),
            attachment("groundcal/b", &[2; 70], None),
        ]);
        match read(&many, small) {
            Err(ReadError::Stream(e)) => {
                assert!(e.to_string().contains("attachments kept"), "{e}")
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn the_python_writers_bags_read_alike_uncompressed_zstd_and_lz4() {
        let read = |name: &str| {
            let path = format!(
                "{}/fuzz/corpus/mcap_bag/tiny-{name}.mcap",
                env!("CARGO_MANIFEST_DIR")
            );
            messages(&std::fs::read(path).unwrap()).unwrap()
        };
        let plain = read("none");
        let topics: Vec<&str> = plain.iter().map(|m| m.0.as_str()).collect();
        assert_eq!(
            topics,
            [
                "/tf",
                "/camera/depth/image_raw",
                "/camera/depth/camera_info"
            ]
        );
        assert_eq!(plain[1].1, "sensor_msgs/msg/Image");
        assert_eq!(plain[1].2, 6);
        assert_eq!(read("zstd"), plain);
        assert_eq!(read("lz4"), plain);
    }

    #[test]
    fn a_length_beyond_the_record_is_an_error_not_an_allocation() {
        // A channel whose topic claims 4 GB (the mcap crate's parser would
        // reserve them first).
        let mut body = Vec::new();
        body.extend_from_slice(&1u16.to_le_bytes());
        body.extend_from_slice(&1u16.to_le_bytes());
        body.extend_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
        body.extend_from_slice(b"/tf");
        let mut file = MAGIC.to_vec();
        file.extend(record(op::CHANNEL, &body));
        let e = messages(&file).unwrap_err();
        assert_eq!(e.offset, 8);
        assert!(
            e.what.contains("the channel's topic of 4294967280 bytes"),
            "{e}"
        );
        // A record longer than the file: named, nothing reserved for it.
        let mut file = MAGIC.to_vec();
        file.push(op::MESSAGE);
        file.extend_from_slice(&(20u64 << 20).to_le_bytes());
        let e = messages(&file).unwrap_err();
        assert!(
            e.what
                .contains("ends inside a record (0 of 20971520 bytes)"),
            "{e}"
        );
        // One longer than a real rosbag2's: refused by its length alone.
        let mut file = MAGIC.to_vec();
        file.push(op::MESSAGE);
        file.extend_from_slice(&(400u64 << 20).to_le_bytes());
        let e = messages(&file).unwrap_err();
        assert!(
            e.what
                .contains("a record of 419430400 bytes (opcode 0x05): more than the 33554432"),
            "{e}"
        );
        // A message on a channel never declared.
        let mut body = vec![7, 0];
        body.extend_from_slice(&[0; 20]);
        let mut file = MAGIC.to_vec();
        file.extend(record(op::MESSAGE, &body));
        assert!(messages(&file).unwrap_err().what.contains("channel 7"));
    }
}
