//! Reading single depth images from files: libfreenect fakenect dumps, 16-bit PGM, PNG and TIFF.
//!
//! Every reader is strict (a depth image that is even slightly off is refused rather than
//! guessed at, because a wrong byte order or unit silently ruins a calibration) and never
//! panics: files come from disk and are untrusted, so sizes are checked before anything is
//! allocated and every failure is an error that names the file.

use std::io::Cursor;
use std::path::{Path, PathBuf};

/// Largest accepted width or height; anything bigger is refused before allocating.
const MAX_SIDE: usize = 4096;
/// Bytes of decoded pixel data in the largest accepted image.
const MAX_PIXEL_BYTES: usize = MAX_SIDE * MAX_SIDE * 2;
/// Largest file read at all: twice the biggest uncompressed image leaves room for headers.
const MAX_FILE_BYTES: u64 = 2 * MAX_PIXEL_BYTES as u64;
/// Kinect 11-bit raw disparity: 2047 means "no reading", nothing can be larger.
const RAW11_MAX: u16 = 2047;

const PNG_SIGNATURE: &[u8] = b"\x89PNG\r\n\x1a\n";

/// What the 16-bit values of a depth image mean (`--units raw11|mm|tum`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DepthUnits {
    /// Kinect 11-bit raw disparity; 2047 = no reading.
    Raw11,
    /// Millimetres; 0 = no reading.
    #[value(name = "mm")]
    Millimetres,
    /// TUM RGB-D convention: 5000 per metre; 0 = no reading.
    Tum,
}

/// One depth image in memory.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthImage {
    pub width: usize,
    pub height: usize,
    /// Row-major, top row first; `width * height` values.
    pub pixels: Vec<u16>,
}

/// Why a depth image could not be read; every message starts with the file's path.
#[derive(Debug, thiserror::Error)]
pub enum DepthImageError {
    #[error("{}: cannot read file: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: file is larger than {max} bytes, too big to be a depth image", path.display())]
    FileTooLarge { path: PathBuf, max: u64 },
    #[error(
        "{}: unrecognised file format: expected a binary PGM ('P5'), PNG or TIFF signature, found {found}",
        path.display()
    )]
    UnknownFormat { path: PathBuf, found: String },
    #[error("{}: malformed PGM header: {message}", path.display())]
    PgmHeader { path: PathBuf, message: String },
    #[error(
        "{}: image size {width}x{height} is not allowed: width and height must each be between 1 and {MAX_SIDE}",
        path.display()
    )]
    Dimensions {
        path: PathBuf,
        width: u64,
        height: u64,
    },
    #[error("{}: PGM maxval is {found}, expected {expected}", path.display())]
    MaxVal {
        path: PathBuf,
        found: u64,
        expected: &'static str,
    },
    #[error(
        "{}: expected {expected} bytes of pixel data after the header, found {found} ({hint})",
        path.display()
    )]
    DataLength {
        path: PathBuf,
        expected: usize,
        found: usize,
        hint: &'static str,
    },
    #[error("{}: pixel ({x}, {y}) is {value}, above the PGM maxval {maxval}", path.display())]
    SampleAboveMaxval {
        path: PathBuf,
        x: usize,
        y: usize,
        value: u16,
        maxval: u16,
    },
    #[error("{}: expected a {expected}, found {found}", path.display())]
    PixelFormat {
        path: PathBuf,
        expected: &'static str,
        found: String,
    },
    #[error("{}: invalid {format} file: {message}", path.display())]
    Decode {
        path: PathBuf,
        format: &'static str,
        message: String,
    },
    #[error(
        "{}: pixel ({x}, {y}) is {value}, above {RAW11_MAX}, the largest Kinect 11-bit raw disparity (wrong units or byte order?)",
        path.display()
    )]
    NotRaw11 {
        path: PathBuf,
        x: usize,
        y: usize,
        value: u16,
    },
}

/// Parses a libfreenect fakenect depth dump: `P5 <w> <h> 65535` then little-endian u16 pixels.
///
/// Fakenect writes the host's (little-endian) bytes, unlike standard PGM; comments are refused
/// because fakenect never writes them and its own reader does not skip them.
pub fn parse_fakenect_pgm(path: &Path, bytes: &[u8]) -> Result<DepthImage, DepthImageError> {
    let mut pixels = Vec::new();
    let (width, height) = parse_fakenect_pgm_into(path, bytes, &mut pixels)?;
    Ok(DepthImage {
        width,
        height,
        pixels,
    })
}

/// [`parse_fakenect_pgm`] into a buffer reused from frame to frame; returns
/// the image's width and height.
pub fn parse_fakenect_pgm_into(
    path: &Path,
    bytes: &[u8],
    pixels: &mut Vec<u16>,
) -> Result<(usize, usize), DepthImageError> {
    let header = parse_pgm_header(path, bytes, false)?;
    if header.maxval != 65535 {
        return Err(DepthImageError::MaxVal {
            path: path.to_path_buf(),
            found: header.maxval,
            expected: "65535 (fakenect depth dump)",
        });
    }
    let data = pixel_data(path, bytes, &header)?;
    pixels.clear();
    pixels.resize(data.len() / 2, 0);
    for (out, c) in pixels.iter_mut().zip(data.chunks_exact(2)) {
        *out = u16::from_le_bytes([c[0], c[1]]);
    }
    Ok((header.width, header.height))
}

/// A fakenect dump's size and where its pixels start, from the first bytes of
/// its file when they hold the whole header: `(width, height, offset)`. `None`
/// for anything else, which [`parse_fakenect_pgm`] on the whole file explains;
/// this lets a reader put the pixels straight into their buffer.
pub fn fakenect_pixels_start(prefix: &[u8]) -> Option<(usize, usize, usize)> {
    let header = parse_pgm_header(Path::new(""), prefix, false).ok()?;
    (header.maxval == 65535).then_some((header.width, header.height, header.data_start))
}

/// Parses a standard binary PGM with 16-bit (big-endian) samples, as written for depth in mm.
///
/// maxval <= 255 means 8-bit samples, which cannot be depth, so it is refused.
pub fn parse_standard_pgm16(path: &Path, bytes: &[u8]) -> Result<DepthImage, DepthImageError> {
    let header = parse_pgm_header(path, bytes, true)?;
    let maxval = match u16::try_from(header.maxval) {
        Ok(m) if m > 255 => m,
        _ => {
            return Err(DepthImageError::MaxVal {
                path: path.to_path_buf(),
                found: header.maxval,
                expected: "256..=65535 (16-bit PGM depth image)",
            })
        }
    };
    let data = pixel_data(path, bytes, &header)?;
    let pixels: Vec<u16> = data
        .chunks_exact(2)
        .map(|c| u16::from_be_bytes([c[0], c[1]]))
        .collect();
    if let Some(i) = pixels.iter().position(|&v| v > maxval) {
        return Err(DepthImageError::SampleAboveMaxval {
            path: path.to_path_buf(),
            x: i % header.width,
            y: i / header.width,
            value: pixels[i],
            maxval,
        });
    }
    Ok(DepthImage {
        width: header.width,
        height: header.height,
        pixels,
    })
}

/// Parses a 16-bit greyscale PNG; anything else is refused with what was found.
pub fn parse_png16(path: &Path, bytes: &[u8]) -> Result<DepthImage, DepthImageError> {
    guard_panics(path, "PNG", || {
        let decode_err = |e: png::DecodingError| decode_error(path, "PNG", e);
        let mut decoder = png::Decoder::new_with_limits(
            Cursor::new(bytes),
            png::Limits {
                bytes: MAX_FILE_BYTES as usize,
            },
        );
        // Keep the samples exactly as stored: no expansion, stripping or gamma.
        decoder.set_transformations(png::Transformations::IDENTITY);
        let mut reader = decoder.read_info().map_err(decode_err)?;
        let info = reader.info();
        let (width, height) = check_dimensions(path, info.width.into(), info.height.into())?;
        if info.bit_depth != png::BitDepth::Sixteen || info.color_type != png::ColorType::Grayscale
        {
            let colour = match info.color_type {
                png::ColorType::Grayscale => "greyscale",
                png::ColorType::Rgb => "RGB",
                png::ColorType::Indexed => "palette",
                png::ColorType::GrayscaleAlpha => "greyscale+alpha",
                png::ColorType::Rgba => "RGBA",
            };
            return Err(DepthImageError::PixelFormat {
                path: path.to_path_buf(),
                expected: "16-bit greyscale PNG",
                found: format!("{}-bit {colour} PNG", info.bit_depth as u8),
            });
        }
        let expected = width * height * 2;
        if reader.output_buffer_size() != expected {
            return Err(DepthImageError::Decode {
                path: path.to_path_buf(),
                format: "PNG",
                message: format!(
                    "decoder wants {} bytes for a {width}x{height} 16-bit image",
                    reader.output_buffer_size()
                ),
            });
        }
        let mut buf = vec![0u8; expected];
        reader.next_frame(&mut buf).map_err(decode_err)?;
        // Reads through to IEND so a file cut off after the pixels is still refused.
        reader.finish().map_err(decode_err)?;
        Ok(DepthImage {
            width,
            height,
            pixels: buf
                .chunks_exact(2)
                .map(|c| u16::from_be_bytes([c[0], c[1]]))
                .collect(),
        })
    })
}

/// Parses a single-page, 16-bit unsigned, single-channel TIFF (any compression `tiff` supports).
pub fn parse_tiff16(path: &Path, bytes: &[u8]) -> Result<DepthImage, DepthImageError> {
    use tiff::decoder::{Decoder, DecodingResult, Limits};
    use tiff::tags::{PhotometricInterpretation, Tag};
    use tiff::ColorType;

    guard_panics(path, "TIFF", || {
        let decode_err = |e: tiff::TiffError| decode_error(path, "TIFF", e);
        let mut limits = Limits::default();
        limits.decoding_buffer_size = MAX_PIXEL_BYTES;
        limits.intermediate_buffer_size = MAX_FILE_BYTES as usize;
        let mut decoder = Decoder::new(Cursor::new(bytes))
            .map_err(decode_err)?
            .with_limits(limits);
        let (w, h) = decoder.dimensions().map_err(decode_err)?;
        let (width, height) = check_dimensions(path, w.into(), h.into())?;
        let wrong_format = |found: String| DepthImageError::PixelFormat {
            path: path.to_path_buf(),
            expected: "16-bit unsigned single-channel TIFF",
            found,
        };
        match decoder.colortype().map_err(decode_err)? {
            ColorType::Gray(16) => {}
            other => {
                return Err(wrong_format(format!(
                    "{} TIFF",
                    describe_tiff_colour(other)
                )))
            }
        }
        // The decoder would invert WhiteIsZero samples, which is meaningless for depth.
        let photometric = decoder
            .find_tag(Tag::PhotometricInterpretation)
            .map_err(decode_err)?
            .map(|v| v.into_u16())
            .transpose()
            .map_err(decode_err)?;
        if photometric == Some(PhotometricInterpretation::WhiteIsZero.to_u16()) {
            return Err(wrong_format(
                "a WhiteIsZero (inverted) greyscale TIFF".to_string(),
            ));
        }
        if decoder.more_images() {
            return Err(wrong_format(
                "a multi-page TIFF (which page is the depth?)".to_string(),
            ));
        }
        let pixels = match decoder.read_image().map_err(decode_err)? {
            DecodingResult::U16(pixels) => pixels,
            DecodingResult::I16(_) => {
                return Err(wrong_format("signed 16-bit TIFF samples".to_string()))
            }
            _ => return Err(wrong_format("non-integer 16-bit TIFF samples".to_string())),
        };
        if pixels.len() != width * height {
            return Err(DepthImageError::Decode {
                path: path.to_path_buf(),
                format: "TIFF",
                message: format!(
                    "decoded {} samples for a {width}x{height} image",
                    pixels.len()
                ),
            });
        }
        Ok(DepthImage {
            width,
            height,
            pixels,
        })
    })
}

/// Reads a depth image file, choosing the parser from its magic bytes.
///
/// A P5 file's byte order cannot be told from its contents, so `units` decides it: Raw11 means
/// a fakenect (little-endian) dump, mm/TUM a standard big-endian PGM. Without `units`, PGM is
/// taken as Raw11 and PNG/TIFF as millimetres. Raw11 images are also checked to hold no value
/// above 2047, which catches a file read with the wrong units or byte order.
pub fn read_depth_image(
    path: &Path,
    units: Option<DepthUnits>,
) -> Result<(DepthImage, DepthUnits), DepthImageError> {
    let bytes = read_bounded(path)?;
    let format = sniff_format(path, &bytes)?;
    let units = units.unwrap_or(match format {
        FileFormat::Pgm => DepthUnits::Raw11,
        FileFormat::Png | FileFormat::Tiff => DepthUnits::Millimetres,
    });
    let image = match (format, units) {
        (FileFormat::Pgm, DepthUnits::Raw11) => parse_fakenect_pgm(path, &bytes)?,
        (FileFormat::Pgm, _) => parse_standard_pgm16(path, &bytes)?,
        (FileFormat::Png, _) => parse_png16(path, &bytes)?,
        (FileFormat::Tiff, _) => parse_tiff16(path, &bytes)?,
    };
    if units == DepthUnits::Raw11 {
        if let Some(i) = image.pixels.iter().position(|&v| v > RAW11_MAX) {
            return Err(DepthImageError::NotRaw11 {
                path: path.to_path_buf(),
                x: i % image.width,
                y: i / image.width,
                value: image.pixels[i],
            });
        }
    }
    Ok((image, units))
}

/// Writes a fakenect depth dump (`P5 <w> <h> 65535\n`, little-endian pixels).
///
/// The pixels are written as they are; if `pixels.len()` is not `width * height` the result
/// is a file that `parse_fakenect_pgm` refuses.
pub fn encode_fakenect_pgm(image: &DepthImage) -> Vec<u8> {
    let mut out = format!("P5 {} {} 65535\n", image.width, image.height).into_bytes();
    out.reserve(image.pixels.len() * 2);
    for p in &image.pixels {
        out.extend_from_slice(&p.to_le_bytes());
    }
    out
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum FileFormat {
    Pgm,
    Png,
    Tiff,
}

fn sniff_format(path: &Path, bytes: &[u8]) -> Result<FileFormat, DepthImageError> {
    if bytes.starts_with(b"P5") {
        Ok(FileFormat::Pgm)
    } else if bytes.starts_with(PNG_SIGNATURE) {
        Ok(FileFormat::Png)
    } else if bytes.starts_with(b"II*\0") || bytes.starts_with(b"MM\0*") {
        Ok(FileFormat::Tiff)
    } else {
        Err(DepthImageError::UnknownFormat {
            path: path.to_path_buf(),
            found: describe_start(bytes),
        })
    }
}

/// Reads the whole file, refusing before reading if it is implausibly large for a depth image.
fn read_bounded(path: &Path) -> Result<Vec<u8>, DepthImageError> {
    use crate::platform::files::ReadError;
    let mut bytes = Vec::new();
    crate::platform::files::read_bounded_into(path, MAX_FILE_BYTES, &mut bytes).map_err(
        |e| match e {
            ReadError::File(f) => DepthImageError::Io {
                path: path.to_path_buf(),
                source: f.source,
            },
            ReadError::TooLarge { .. } => DepthImageError::FileTooLarge {
                path: path.to_path_buf(),
                max: MAX_FILE_BYTES,
            },
        },
    )?;
    Ok(bytes)
}

struct PgmHeader {
    width: usize,
    height: usize,
    maxval: u64,
    /// Offset of the first pixel byte.
    data_start: usize,
}

/// Parses `P5 <w> <h> <maxval>` plus the single whitespace byte that ends a PGM header.
fn parse_pgm_header(
    path: &Path,
    bytes: &[u8],
    allow_comments: bool,
) -> Result<PgmHeader, DepthImageError> {
    let err = |message: String| DepthImageError::PgmHeader {
        path: path.to_path_buf(),
        message,
    };
    if !bytes.starts_with(b"P5") {
        return Err(err(format!(
            "expected magic 'P5', found {}",
            describe_start(bytes)
        )));
    }
    let mut pos = 2;
    let mut fields = [0u64; 3];
    for (field, name) in fields.iter_mut().zip(["width", "height", "maxval"]) {
        let before = pos;
        pos = skip_separators(bytes, pos, allow_comments);
        if pos == before {
            return Err(err(format!(
                "expected whitespace before the {name}, found {}",
                describe_byte(bytes.get(pos))
            )));
        }
        let digits_start = pos;
        let mut value = 0u64;
        while let Some(d) = bytes.get(pos).filter(|b| b.is_ascii_digit()) {
            value = value.saturating_mul(10).saturating_add(u64::from(d - b'0'));
            pos += 1;
        }
        if pos == digits_start {
            return Err(err(format!(
                "expected the {name} as a decimal number, found {}",
                describe_byte(bytes.get(pos))
            )));
        }
        match bytes.get(pos) {
            Some(b) if b.is_ascii_whitespace() => {}
            Some(b'#') if allow_comments && name != "maxval" => {}
            other => {
                return Err(err(format!(
                    "expected whitespace after the {name}, found {}",
                    describe_byte(other)
                )))
            }
        }
        *field = value;
    }
    let [width, height, maxval] = fields;
    let (width, height) = check_dimensions(path, width, height)?;
    // Exactly one whitespace byte separates maxval from the pixels (checked above).
    Ok(PgmHeader {
        width,
        height,
        maxval,
        data_start: pos + 1,
    })
}

/// Skips PGM header whitespace and, if allowed, `#` comments running to the end of a line.
fn skip_separators(bytes: &[u8], mut pos: usize, allow_comments: bool) -> usize {
    loop {
        match bytes.get(pos) {
            Some(b) if b.is_ascii_whitespace() => pos += 1,
            Some(b'#') if allow_comments => {
                while let Some(&b) = bytes.get(pos) {
                    if b == b'\n' || b == b'\r' {
                        break;
                    }
                    pos += 1;
                }
            }
            _ => return pos,
        }
    }
}

/// Returns exactly the pixel bytes, refusing short and over-long files alike.
fn pixel_data<'a>(
    path: &Path,
    bytes: &'a [u8],
    header: &PgmHeader,
) -> Result<&'a [u8], DepthImageError> {
    let expected = header.width * header.height * 2;
    let data = bytes.get(header.data_start..).unwrap_or(&[]);
    if data.len() == expected {
        return Ok(data);
    }
    let hint = if data.len() < expected {
        "truncated file?"
    } else if data.len() == expected + 1 && data.first().is_some_and(u8::is_ascii_whitespace) {
        "more than one whitespace byte after maxval, e.g. CRLF?"
    } else {
        "trailing data after the pixels?"
    };
    Err(DepthImageError::DataLength {
        path: path.to_path_buf(),
        expected,
        found: data.len(),
        hint,
    })
}

/// Refuses sizes outside 1..=4096 per side, before any pixel buffer is allocated.
fn check_dimensions(
    path: &Path,
    width: u64,
    height: u64,
) -> Result<(usize, usize), DepthImageError> {
    let ok = |v: u64| (1..=MAX_SIDE as u64).contains(&v);
    if ok(width) && ok(height) {
        Ok((width as usize, height as usize))
    } else {
        Err(DepthImageError::Dimensions {
            path: path.to_path_buf(),
            width,
            height,
        })
    }
}

fn decode_error(path: &Path, format: &'static str, e: impl std::fmt::Display) -> DepthImageError {
    DepthImageError::Decode {
        path: path.to_path_buf(),
        format,
        message: e.to_string(),
    }
}

/// Turns a panic inside a third-party decoder into an error: malformed input must never abort
/// the caller, and decoders have had panics on fuzzed files before.
fn guard_panics<T>(
    path: &Path,
    format: &'static str,
    f: impl FnOnce() -> Result<T, DepthImageError>,
) -> Result<T, DepthImageError> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).unwrap_or_else(|_| {
        Err(DepthImageError::Decode {
            path: path.to_path_buf(),
            format,
            message: "the decoder panicked on malformed data".to_string(),
        })
    })
}

fn describe_tiff_colour(c: tiff::ColorType) -> String {
    use tiff::ColorType as C;
    match c {
        C::Gray(b) => format!("{b}-bit greyscale"),
        C::RGB(b) => format!("{b}-bit RGB"),
        C::Palette(b) => format!("{b}-bit palette"),
        C::GrayA(b) => format!("{b}-bit greyscale+alpha"),
        C::RGBA(b) => format!("{b}-bit RGBA"),
        C::CMYK(b) => format!("{b}-bit CMYK"),
        C::YCbCr(b) => format!("{b}-bit YCbCr"),
    }
}

fn describe_byte(b: Option<&u8>) -> String {
    match b {
        None => "end of file".to_string(),
        Some(&b) if b.is_ascii_graphic() => format!("'{}'", b as char),
        Some(&b) => format!("byte 0x{b:02x}"),
    }
}

fn describe_start(bytes: &[u8]) -> String {
    if bytes.is_empty() {
        return "an empty file".to_string();
    }
    let shown: Vec<String> = bytes.iter().take(8).map(|b| format!("{b:02x}")).collect();
    format!("bytes {}", shown.join(" "))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Path of a file in the shared data folder: beside the crate, or from
    /// `GROUNDCAL_SHARED_DATA`, or at `/work/shared/data` (for builds from elsewhere).
    fn shared_data(rel: &str) -> PathBuf {
        let beside = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data"));
        let candidates = [
            Some(beside),
            std::env::var_os("GROUNDCAL_SHARED_DATA").map(PathBuf::from),
            Some(PathBuf::from("/work/shared/data")),
        ];
        candidates
            .into_iter()
            .flatten()
            .map(|dir| dir.join(rel))
            .find(|p| p.exists())
            .unwrap_or_else(|| panic!("shared data file {rel} not found"))
    }

    /// A unique scratch file path, removed when dropped.
    struct TempFile(PathBuf);
    impl TempFile {
        fn new(name: &str, bytes: &[u8]) -> Self {
            let path = std::env::temp_dir().join(format!(
                "groundcal-depth-image-{}-{name}",
                std::process::id()
            ));
            std::fs::write(&path, bytes).unwrap();
            TempFile(path)
        }
    }
    impl Drop for TempFile {
        fn drop(&mut self) {
            let _ = std::fs::remove_file(&self.0);
        }
    }

    fn p(s: &str) -> &Path {
        Path::new(s)
    }

    fn expect_err(
        result: Result<DepthImage, DepthImageError>,
        path: &str,
        needle: &str,
    ) -> DepthImageError {
        let err = result.expect_err("expected an error");
        let msg = err.to_string();
        assert!(
            msg.starts_with(path),
            "message {msg:?} does not start with {path:?}"
        );
        assert!(
            msg.contains(needle),
            "message {msg:?} does not mention {needle:?}"
        );
        err
    }

    fn ramp(width: usize, height: usize) -> DepthImage {
        DepthImage {
            width,
            height,
            pixels: (0..width * height)
                .map(|i| (i * 7919 % 65536) as u16)
                .collect(),
        }
    }

    fn pgm(header: &str, data: &[u8]) -> Vec<u8> {
        let mut v = header.as_bytes().to_vec();
        v.extend_from_slice(data);
        v
    }

    fn encode_png(
        width: u32,
        height: u32,
        depth: png::BitDepth,
        colour: png::ColorType,
        data: &[u8],
    ) -> Vec<u8> {
        let mut out = Vec::new();
        let mut enc = png::Encoder::new(&mut out, width, height);
        enc.set_depth(depth);
        enc.set_color(colour);
        let mut writer = enc.write_header().unwrap();
        writer.write_image_data(data).unwrap();
        writer.finish().unwrap();
        out
    }

    fn png16(image: &DepthImage) -> Vec<u8> {
        let data: Vec<u8> = image.pixels.iter().flat_map(|v| v.to_be_bytes()).collect();
        encode_png(
            image.width as u32,
            image.height as u32,
            png::BitDepth::Sixteen,
            png::ColorType::Grayscale,
            &data,
        )
    }

    fn tiff_gray16(image: &DepthImage) -> Vec<u8> {
        let mut out = Cursor::new(Vec::new());
        tiff::encoder::TiffEncoder::new(&mut out)
            .unwrap()
            .write_image::<tiff::encoder::colortype::Gray16>(
                image.width as u32,
                image.height as u32,
                &image.pixels,
            )
            .unwrap();
        out.into_inner()
    }

    #[test]
    fn units_parse() {
        let units = |s: &str| <DepthUnits as clap::ValueEnum>::from_str(s, false).ok();
        assert_eq!(units("raw11"), Some(DepthUnits::Raw11));
        assert_eq!(units("mm"), Some(DepthUnits::Millimetres));
        assert_eq!(units("tum"), Some(DepthUnits::Tum));
        assert_eq!(units("MM"), None);
        assert_eq!(units(""), None);
    }

    #[test]
    fn fakenect_round_trip() {
        for (w, h) in [(1, 1), (3, 2), (640, 480)] {
            let image = ramp(w, h);
            let bytes = encode_fakenect_pgm(&image);
            assert!(bytes.starts_with(format!("P5 {w} {h} 65535\n").as_bytes()));
            assert_eq!(parse_fakenect_pgm(p("x.pgm"), &bytes).unwrap(), image);
        }
    }

    #[test]
    fn fakenect_is_little_endian() {
        let img = parse_fakenect_pgm(
            p("x.pgm"),
            &pgm("P5 2 1 65535\n", &[0xff, 0x07, 0x01, 0x02]),
        )
        .unwrap();
        assert_eq!(img.pixels, vec![2047, 0x0201]);
    }

    #[test]
    fn fakenect_header_whitespace_as_pgm_allows() {
        for header in [
            "P5\n2\n1\n65535\n",
            "P5  2\t1\r\n65535 ",
            "P5\n2 1\n65535\t",
        ] {
            let img = parse_fakenect_pgm(p("x.pgm"), &pgm(header, &[1, 0, 2, 0])).unwrap();
            assert_eq!(img.pixels, vec![1, 2], "header {header:?}");
        }
    }

    #[test]
    fn truncated_is_an_error_naming_path() {
        let err = expect_err(
            parse_fakenect_pgm(p("frames/d-1.pgm"), &pgm("P5 640 480 65535\n", &[0; 1000])),
            "frames/d-1.pgm",
            "truncated",
        );
        assert_eq!(
            err.to_string(),
            "frames/d-1.pgm: expected 614400 bytes of pixel data after the header, found 1000 (truncated file?)"
        );
        expect_err(
            parse_fakenect_pgm(p("a.pgm"), b"P5 640 480 65535\n"),
            "a.pgm",
            "found 0",
        );
    }

    #[test]
    fn over_long_is_an_error() {
        let mut bytes = encode_fakenect_pgm(&ramp(4, 3));
        bytes.extend_from_slice(&[0, 0]);
        expect_err(
            parse_fakenect_pgm(p("long.pgm"), &bytes),
            "long.pgm",
            "trailing data",
        );
        // Two bytes after maxval (CRLF) shifts every pixel by one byte: refused with a hint.
        expect_err(
            parse_fakenect_pgm(p("crlf.pgm"), &pgm("P5 2 1 65535\r\n", &[1, 0, 2, 0])),
            "crlf.pgm",
            "CRLF",
        );
    }

    #[test]
    fn wrong_maxval_is_an_error() {
        for maxval in ["255", "2047", "65536", "0"] {
            expect_err(
                parse_fakenect_pgm(p("m.pgm"), &pgm(&format!("P5 2 1 {maxval}\n"), &[0; 4])),
                "m.pgm",
                &format!("maxval is {maxval}, expected 65535"),
            );
        }
    }

    #[test]
    fn garbage_header_is_an_error() {
        let cases: [(&[u8], &str); 10] = [
            (b"", "expected magic 'P5', found an empty file"),
            (b"P6 2 1 65535\n\0\0\0\0", "expected magic 'P5'"),
            (b"GIF89a", "expected magic 'P5'"),
            (
                b"P5",
                "expected whitespace before the width, found end of file",
            ),
            (
                b"P52 1 65535\n\0\0\0\0",
                "expected whitespace before the width",
            ),
            (
                b"P5 abc 1 65535\n",
                "expected the width as a decimal number, found 'a'",
            ),
            (b"P5 -2 1 65535\n", "expected the width as a decimal number"),
            (
                b"P5 2x1 65535\n",
                "expected whitespace after the width, found 'x'",
            ),
            (
                b"P5 2 1 65535",
                "expected whitespace after the maxval, found end of file",
            ),
            (
                b"P5 2 1 65535\x01\x00\x02\x00",
                "expected whitespace after the maxval, found byte 0x01",
            ),
        ];
        for (bytes, needle) in cases {
            expect_err(parse_fakenect_pgm(p("g.pgm"), bytes), "g.pgm", needle);
        }
        // fakenect never writes comments, and its reader would not skip them.
        expect_err(
            parse_fakenect_pgm(p("c.pgm"), &pgm("P5 # hi\n2 1 65535\n", &[0; 4])),
            "c.pgm",
            "expected the width as a decimal number, found '#'",
        );
    }

    #[test]
    fn zero_or_huge_size_is_an_error() {
        for (header, w, h) in [
            ("P5 0 480 65535\n", "0", "480"),
            ("P5 640 0 65535\n", "640", "0"),
            ("P5 4097 1 65535\n", "4097", "1"),
            (
                "P5 1 99999999999999999999999 65535\n",
                "1",
                "18446744073709551615",
            ),
        ] {
            expect_err(
                parse_fakenect_pgm(p("z.pgm"), header.as_bytes()),
                "z.pgm",
                &format!("image size {w}x{h} is not allowed"),
            );
        }
        let max = parse_fakenect_pgm(p("big.pgm"), &encode_fakenect_pgm(&ramp(4096, 1))).unwrap();
        assert_eq!((max.width, max.height), (4096, 1));
    }

    #[test]
    fn standard_pgm16_is_big_endian_and_allows_comments() {
        let bytes = pgm(
            "P5\n# depth in mm\n2 # width\n1\n#x\n65535\n",
            &[0x03, 0xe8, 0x00, 0x00],
        );
        let img = parse_standard_pgm16(p("s.pgm"), &bytes).unwrap();
        assert_eq!((img.width, img.height, img.pixels), (2, 1, vec![1000, 0]));
        let img = parse_standard_pgm16(p("s.pgm"), &pgm("P5 1 1 4095\n", &[0x0f, 0xff])).unwrap();
        assert_eq!(img.pixels, vec![4095]);
    }

    #[test]
    fn standard_pgm16_refusals() {
        expect_err(
            parse_standard_pgm16(p("8bit.pgm"), &pgm("P5 2 1 255\n", &[1, 2])),
            "8bit.pgm",
            "maxval is 255, expected 256..=65535",
        );
        expect_err(
            parse_standard_pgm16(p("big.pgm"), &pgm("P5 1 1 70000\n", &[1, 2])),
            "big.pgm",
            "maxval is 70000",
        );
        expect_err(
            parse_standard_pgm16(
                p("over.pgm"),
                &pgm("P5 2 2 4095\n", &[0, 0, 0, 0, 0, 0, 0x10, 0]),
            ),
            "over.pgm",
            "pixel (1, 1) is 4096, above the PGM maxval 4095",
        );
        expect_err(
            parse_standard_pgm16(p("short.pgm"), &pgm("P5 2 2 4095\n", &[0, 0])),
            "short.pgm",
            "expected 8 bytes of pixel data after the header, found 2 (truncated file?)",
        );
    }

    #[test]
    fn png16_round_trip() {
        let image = ramp(37, 23);
        assert_eq!(parse_png16(p("d.png"), &png16(&image)).unwrap(), image);
    }

    #[test]
    fn png_other_formats_are_refused() {
        let grey8 = encode_png(
            2,
            2,
            png::BitDepth::Eight,
            png::ColorType::Grayscale,
            &[0; 4],
        );
        expect_err(
            parse_png16(p("g8.png"), &grey8),
            "g8.png",
            "found 8-bit greyscale PNG",
        );
        let rgb16 = encode_png(2, 1, png::BitDepth::Sixteen, png::ColorType::Rgb, &[0; 12]);
        expect_err(
            parse_png16(p("rgb.png"), &rgb16),
            "rgb.png",
            "found 16-bit RGB PNG",
        );
        let rgba8 = encode_png(1, 1, png::BitDepth::Eight, png::ColorType::Rgba, &[0; 4]);
        expect_err(
            parse_png16(p("rgba.png"), &rgba8),
            "rgba.png",
            "expected a 16-bit greyscale PNG",
        );
    }

    #[test]
    fn png_truncated_or_oversized_is_refused() {
        let bytes = png16(&ramp(64, 64));
        // Cut inside the pixel data, and just before IEND.
        for cut in [bytes.len() / 2, bytes.len() - 12] {
            expect_err(
                parse_png16(p("cut.png"), &bytes[..cut]),
                "cut.png",
                "invalid PNG file",
            );
        }
        let wide = png16(&ramp(4097, 1));
        expect_err(
            parse_png16(p("wide.png"), &wide),
            "wide.png",
            "4097x1 is not allowed",
        );
        // A header claiming 100000x100000 must be refused without allocating 20 GB.
        let bomb = crafted_png(100_000, 100_000);
        expect_err(parse_png16(p("bomb.png"), &bomb), "bomb.png", "not allowed");
    }

    /// A hand-made 16-bit grey PNG of the given size, all zeros (truncated if huge).
    fn crafted_png(width: u32, height: u32) -> Vec<u8> {
        fn crc32(bytes: &[u8]) -> u32 {
            let mut crc = !0u32;
            for &b in bytes {
                crc ^= u32::from(b);
                for _ in 0..8 {
                    crc = if crc & 1 != 0 {
                        (crc >> 1) ^ 0xedb8_8320
                    } else {
                        crc >> 1
                    };
                }
            }
            !crc
        }
        fn chunk(out: &mut Vec<u8>, kind: &[u8], data: &[u8]) {
            out.extend_from_slice(&(data.len() as u32).to_be_bytes());
            let mut body = kind.to_vec();
            body.extend_from_slice(data);
            out.extend_from_slice(&body);
            out.extend_from_slice(&crc32(&body).to_be_bytes());
        }
        let mut ihdr = Vec::new();
        ihdr.extend_from_slice(&width.to_be_bytes());
        ihdr.extend_from_slice(&height.to_be_bytes());
        ihdr.extend_from_slice(&[16, 0, 0, 0, 0]);
        let mut out = PNG_SIGNATURE.to_vec();
        chunk(&mut out, b"IHDR", &ihdr);
        // Zero-filtered black rows in one stored (uncompressed) zlib block, capped at 1000
        // bytes: enough for a small image, a few bytes of a huge one.
        let raw_len = ((u64::from(width) * 2 + 1) * u64::from(height)).min(1000) as u16;
        let mut zlib = vec![0x78, 0x01, 0x01];
        zlib.extend_from_slice(&raw_len.to_le_bytes());
        zlib.extend_from_slice(&(!raw_len).to_le_bytes());
        zlib.resize(zlib.len() + usize::from(raw_len), 0);
        // Adler-32 of all-zero data: a = 1, b = length.
        zlib.extend_from_slice(&((u32::from(raw_len) << 16) | 1).to_be_bytes());
        chunk(&mut out, b"IDAT", &zlib);
        chunk(&mut out, b"IEND", &[]);
        out
    }

    #[test]
    fn crafted_png_is_valid_at_small_size() {
        // Guards the bomb test: the crafted file must fail on size, not on being malformed.
        let img = parse_png16(p("ok.png"), &crafted_png(3, 2)).unwrap();
        assert_eq!((img.width, img.height, img.pixels), (3, 2, vec![0; 6]));
    }

    #[test]
    fn tiff16_round_trip() {
        let image = ramp(33, 17);
        assert_eq!(
            parse_tiff16(p("d.tiff"), &tiff_gray16(&image)).unwrap(),
            image
        );
    }

    #[test]
    fn tiff_other_formats_are_refused() {
        let mut rgb = Cursor::new(Vec::new());
        tiff::encoder::TiffEncoder::new(&mut rgb)
            .unwrap()
            .write_image::<tiff::encoder::colortype::RGB8>(2, 1, &[0; 6])
            .unwrap();
        expect_err(
            parse_tiff16(p("rgb.tiff"), rgb.get_ref()),
            "rgb.tiff",
            "found 8-bit RGB TIFF",
        );
        let mut signed = Cursor::new(Vec::new());
        tiff::encoder::TiffEncoder::new(&mut signed)
            .unwrap()
            .write_image::<tiff::encoder::colortype::GrayI16>(2, 1, &[-1, 5])
            .unwrap();
        expect_err(
            parse_tiff16(p("i16.tiff"), signed.get_ref()),
            "i16.tiff",
            "signed 16-bit",
        );
        let mut f32s = Cursor::new(Vec::new());
        tiff::encoder::TiffEncoder::new(&mut f32s)
            .unwrap()
            .write_image::<tiff::encoder::colortype::Gray32Float>(2, 1, &[1.0, 2.0])
            .unwrap();
        expect_err(
            parse_tiff16(p("f.tiff"), f32s.get_ref()),
            "f.tiff",
            "32-bit greyscale",
        );
    }

    #[test]
    fn tiff_truncated_or_oversized_is_refused() {
        let bytes = tiff_gray16(&ramp(64, 64));
        for cut in [0, 4, 9, bytes.len() / 2] {
            assert!(
                parse_tiff16(p("cut.tiff"), &bytes[..cut]).is_err(),
                "cut at {cut}"
            );
        }
        let wide = tiff_gray16(&ramp(4097, 1));
        expect_err(
            parse_tiff16(p("wide.tiff"), &wide),
            "wide.tiff",
            "4097x1 is not allowed",
        );
        let bomb = crafted_tiff(100_000, 100_000);
        expect_err(
            parse_tiff16(p("bomb.tiff"), &bomb),
            "bomb.tiff",
            "100000x100000 is not allowed",
        );
    }

    /// A little-endian, uncompressed 16-bit grey TIFF header claiming the given size.
    fn crafted_tiff(width: u32, height: u32) -> Vec<u8> {
        let entries: [(u16, u16, u32); 9] = [
            (256, 4, width),     // ImageWidth, LONG
            (257, 4, height),    // ImageLength
            (258, 3, 16),        // BitsPerSample, SHORT
            (259, 3, 1),         // Compression: none
            (262, 3, 1),         // BlackIsZero
            (273, 4, 8),         // StripOffsets
            (277, 3, 1),         // SamplesPerPixel
            (278, 4, height),    // RowsPerStrip
            (279, 4, 2 * width), // StripByteCounts (wraps; never reached)
        ];
        let mut out = b"II*\0".to_vec();
        out.extend_from_slice(&8u32.to_le_bytes());
        out.extend_from_slice(&(entries.len() as u16).to_le_bytes());
        for (tag, kind, value) in entries {
            out.extend_from_slice(&tag.to_le_bytes());
            out.extend_from_slice(&kind.to_le_bytes());
            out.extend_from_slice(&1u32.to_le_bytes());
            out.extend_from_slice(&value.to_le_bytes());
        }
        out.extend_from_slice(&0u32.to_le_bytes());
        out
    }

    #[test]
    fn read_dispatches_on_magic_and_units() {
        let image = ramp(5, 4);
        let raw11 = DepthImage {
            width: 3,
            height: 1,
            pixels: vec![0, 1000, 2047],
        };
        let fakenect = TempFile::new("dispatch.pgm", &encode_fakenect_pgm(&raw11));
        assert_eq!(
            read_depth_image(&fakenect.0, None).unwrap(),
            (raw11.clone(), DepthUnits::Raw11)
        );
        // The same bytes as a standard PGM are big-endian: 1000 LE = 0x03e8 -> 0xe803 BE.
        let (be, units) = read_depth_image(&fakenect.0, Some(DepthUnits::Millimetres)).unwrap();
        assert_eq!(
            (be.pixels, units),
            (vec![0, 0xe803, 0xff07], DepthUnits::Millimetres)
        );

        let png = TempFile::new("dispatch.png", &png16(&image));
        assert_eq!(
            read_depth_image(&png.0, None).unwrap(),
            (image.clone(), DepthUnits::Millimetres)
        );
        assert_eq!(
            read_depth_image(&png.0, Some(DepthUnits::Tum)).unwrap().1,
            DepthUnits::Tum
        );
        let tiff = TempFile::new("dispatch.tiff", &tiff_gray16(&image));
        assert_eq!(
            read_depth_image(&tiff.0, None).unwrap(),
            (image, DepthUnits::Millimetres)
        );
    }

    #[test]
    fn read_refuses_raw11_values_above_2047() {
        let mm = DepthImage {
            width: 2,
            height: 2,
            pixels: vec![0, 0, 0, 2048],
        };
        let file = TempFile::new("raw11.pgm", &encode_fakenect_pgm(&mm));
        let err = read_depth_image(&file.0, None).unwrap_err().to_string();
        assert!(err.starts_with(&file.0.display().to_string()), "{err}");
        assert!(err.contains("pixel (1, 1) is 2048, above 2047"), "{err}");
        assert!(read_depth_image(&file.0, Some(DepthUnits::Millimetres)).is_ok());
    }

    #[test]
    fn read_errors_name_the_path() {
        let missing = std::env::temp_dir().join("groundcal-depth-image-does-not-exist.pgm");
        let err = read_depth_image(&missing, None).unwrap_err().to_string();
        assert!(
            err.starts_with(&missing.display().to_string()) && err.contains("cannot read"),
            "{err}"
        );
        for (name, bytes, needle) in [
            ("empty.bin", &b""[..], "found an empty file"),
            (
                "gif.bin",
                &b"GIF89a\x01\x00"[..],
                "found bytes 47 49 46 38 39 61 01 00",
            ),
            (
                "p2.pgm",
                &b"P2 1 1 65535\n0\n"[..],
                "expected a binary PGM ('P5'), PNG or TIFF",
            ),
        ] {
            let file = TempFile::new(name, bytes);
            let err = read_depth_image(&file.0, None).unwrap_err().to_string();
            assert!(err.starts_with(&file.0.display().to_string()), "{err}");
            assert!(err.contains(needle), "{err}");
        }
    }

    #[test]
    fn real_pcl_tiff_is_mm_depth() {
        let path = shared_data("real/pcl_floor_tilted_frame_20121214T142255.814212_depth.tiff");
        let (img, units) = read_depth_image(&path, None).unwrap();
        assert_eq!(
            (img.width, img.height, units),
            (640, 480, DepthUnits::Millimetres)
        );
        let zeros = img.pixels.iter().filter(|&&v| v == 0).count() as f64 / img.pixels.len() as f64;
        assert!((0.11..0.12).contains(&zeros), "zero fraction {zeros}");
        let valid = img.pixels.iter().copied().filter(|&v| v != 0);
        let (min, max) = (valid.clone().min().unwrap(), valid.max().unwrap());
        assert!(
            (650..=700).contains(&min) && (1700..=1730).contains(&max),
            "{min}..{max}"
        );
    }

    #[test]
    fn real_tum_png_is_tum_depth() {
        let path = shared_data("real/tum_office_TUM_depth.png");
        let (img, units) = read_depth_image(&path, Some(DepthUnits::Tum)).unwrap();
        assert_eq!((img.width, img.height, units), (640, 480, DepthUnits::Tum));
        // Observed: 19.2% zeros, valid 7320..46655 (1.46 m .. 9.33 m), median ~12075 (2.4 m).
        let zeros = img.pixels.iter().filter(|&&v| v == 0).count() as f64 / img.pixels.len() as f64;
        assert!((0.18..0.21).contains(&zeros), "zero fraction {zeros}");
        let mut valid: Vec<u16> = img.pixels.iter().copied().filter(|&v| v != 0).collect();
        valid.sort_unstable();
        let median_m = f64::from(valid[valid.len() / 2]) / 5000.0;
        assert!((2.2..2.6).contains(&median_m), "median {median_m} m");
        assert!(valid[0] >= 5000 / 2 && *valid.last().unwrap() <= 50_000);
    }

    #[test]
    fn real_fakenect_dump_is_raw11() {
        let path = shared_data("sample-12/kinect/d-1700000000.001000-2001000.pgm");
        let (img, units) = read_depth_image(&path, None).unwrap();
        assert_eq!(
            (img.width, img.height, units),
            (640, 480, DepthUnits::Raw11)
        );
        assert!(img.pixels.iter().all(|&v| v <= 2047));
        assert!(
            img.pixels.iter().any(|&v| v < 2047),
            "no valid reading at all"
        );
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(encode_fakenect_pgm(&img), bytes);
    }

    #[test]
    fn damaged_real_files_give_errors_not_panics() {
        type Parser = fn(&Path, &[u8]) -> Result<DepthImage, DepthImageError>;
        let files: [(&str, Parser); 3] = [
            (
                "real/pcl_floor_tilted_frame_20121214T142255.814212_depth.tiff",
                parse_tiff16,
            ),
            ("real/tum_office_TUM_depth.png", parse_png16),
            (
                "sample-12/kinect/d-1700000000.001000-2001000.pgm",
                parse_fakenect_pgm,
            ),
        ];
        for (rel, parse) in files {
            let bytes = std::fs::read(shared_data(rel)).unwrap();
            let check = |damaged: &[u8], what: String| {
                if let Err(e) = parse(p("damaged"), damaged) {
                    let msg = e.to_string();
                    assert!(
                        msg.starts_with("damaged") && !msg.contains("panicked"),
                        "{rel} {what}: {msg}"
                    );
                }
            };
            for i in 0..40 {
                let cut = bytes.len() * i / 40;
                check(&bytes[..cut], format!("cut at {cut}"));
            }
            let mut state = 0x2545_f491_4f6c_dd1du64;
            for round in 0..40 {
                let mut damaged = bytes.clone();
                for _ in 0..4 {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    // Mostly hit the header and early structures, where parsers branch.
                    let limit = if round % 2 == 0 {
                        512.min(damaged.len())
                    } else {
                        damaged.len()
                    };
                    let at = (state % limit as u64) as usize;
                    damaged[at] ^= (state >> 32) as u8 | 1;
                }
                check(&damaged, format!("flip round {round}"));
            }
        }
    }
}
