//! The messages of an MCAP file, read as a stream: record by record from any
//! `Read`, chunks decompressed one at a time (zstd or lz4, as rosbag2 writes
//! them, or none), so that a bag of gigabytes takes the memory of one chunk.
//! The summary at the end is not needed and not read.
//!
//! Every length is checked before anything is allocated for it: a record or
//! a chunk larger than [`Limits`] allow, a chunk that decompresses to another
//! size or CRC than its header says, a message on a channel never declared
//! are errors that give the byte offset, never a panic.

use std::collections::HashMap;
use std::io::Read;

use mcap::records::{self, Record};

/// MCAP's magic, at both ends of a file.
pub const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// How large one record and one decompressed chunk may be.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    pub record_bytes: u64,
    pub chunk_bytes: u64,
}

impl Default for Limits {
    /// 512 MiB each: rosbag2 writes chunks of about 1 MiB, and a whole
    /// 640 × 480 image is 1.2 MB.
    fn default() -> Self {
        Self {
            record_bytes: 512 << 20,
            chunk_bytes: 512 << 20,
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
#[derive(Default)]
struct Declarations {
    schemas: HashMap<u16, String>,
    channels: HashMap<u16, ChannelInfo>,
}

/// Reads every message of an MCAP file from `source`, in file order, and
/// hands those whose topic `wanted` accepts to `each` (which may stop the
/// pass with its own error).
pub fn for_each_message<R: Read, E>(
    mut source: R,
    limits: Limits,
    wanted: impl Fn(&str) -> bool,
    mut each: impl FnMut(StreamMessage<'_>) -> Result<(), E>,
) -> Result<StreamCounts, ReadError<E>> {
    let mut magic = [0u8; 8];
    read_exact(&mut source, &mut magic, 0, "the file's magic")?;
    if &magic != MAGIC {
        return Err(stream_error(
            0,
            "not an MCAP file (its first 8 bytes are not MCAP's magic)",
        ));
    }
    let mut offset = 8u64;
    let mut declared = Declarations::default();
    let mut counts = StreamCounts::default();
    let mut body = Vec::new();
    let mut chunk = Vec::new();
    loop {
        let mut opcode_and_length = [0u8; 9];
        // The end: a file cut after a whole record still gives its messages
        // (a bag whose recorder was killed has no summary).
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
        // Grown as the bytes come: a length that claims more than the file
        // holds costs no memory.
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
        let record = mcap::read::parse_record(opcode, &body)
            .map_err(|e| stream_error(record_offset, format!("record 0x{opcode:02x}: {e}")))?;
        match record {
            Record::Chunk { header, data } => {
                counts.chunks += 1;
                decompress(&header, &data, limits, &mut chunk)
                    .map_err(|what| stream_error(record_offset, what))?;
                for inner in mcap::read::LinearReader::sans_magic(&chunk) {
                    let inner = inner.map_err(|e| {
                        stream_error(record_offset, format!("a record in the chunk: {e}"))
                    })?;
                    dispatch(
                        inner,
                        record_offset,
                        &mut declared,
                        &wanted,
                        &mut each,
                        &mut counts,
                    )?;
                }
            }
            Record::DataEnd(_) => return Ok(counts),
            other => dispatch(
                other,
                record_offset,
                &mut declared,
                &wanted,
                &mut each,
                &mut counts,
            )?,
        }
    }
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

fn dispatch<E>(
    record: Record<'_>,
    offset: u64,
    declared: &mut Declarations,
    wanted: &impl Fn(&str) -> bool,
    each: &mut impl FnMut(StreamMessage<'_>) -> Result<(), E>,
    counts: &mut StreamCounts,
) -> Result<(), ReadError<E>> {
    match record {
        Record::Schema { header, .. } => {
            declared.schemas.insert(header.id, header.name);
        }
        Record::Channel(records::Channel {
            id,
            schema_id,
            topic,
            message_encoding,
            ..
        }) => {
            declared.channels.insert(
                id,
                ChannelInfo {
                    topic,
                    schema_id,
                    encoding: message_encoding,
                },
            );
        }
        Record::Message { header, data } => {
            let Some(channel) = declared.channels.get(&header.channel_id) else {
                return Err(stream_error(
                    offset,
                    format!(
                        "a message on channel {}, which no Channel record declared before it",
                        header.channel_id
                    ),
                ));
            };
            if !wanted(&channel.topic) {
                return Ok(());
            }
            counts.messages += 1;
            let schema = declared
                .schemas
                .get(&channel.schema_id)
                .map_or("", String::as_str);
            each(StreamMessage {
                topic: &channel.topic,
                schema,
                encoding: &channel.encoding,
                log_time: header.log_time,
                data: &data,
            })
            .map_err(ReadError::Stopped)?;
        }
        _ => {}
    }
    Ok(())
}

/// A chunk's records into `out`, checked against its header's size and CRC.
fn decompress(
    header: &records::ChunkHeader,
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
