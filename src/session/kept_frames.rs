//! A pose's depth frames kept, compressed, until the solve: when the ground
//! fit's band cut a depth pattern's peaks, the frames are fitted again about
//! its estimate (docs/method.md, "A pattern beyond the fit's band"), and a
//! live session has no recording to read them from.
//!
//! Each row is kept as the differences of its neighbouring raw values,
//! compressed with LZ4: the ground changes slowly along a row, so most
//! differences are a few raw units (measured in `keeps_a_frame_exactly`).

use groundcal_hal::DepthFrame;

/// One pose's frames, compressed.
pub struct KeptFrames {
    width: usize,
    frames: Vec<Vec<u8>>,
}

impl KeptFrames {
    /// Keeps `frames` (all of one size, as the session checks).
    pub fn keep(frames: &[DepthFrame]) -> Self {
        let width = frames.first().map_or(0, |f| f.width);
        let frames = frames
            .iter()
            .map(|frame| {
                let mut bytes = Vec::with_capacity(frame.raw.len() * 2);
                for row in frame.raw.chunks(width.max(1)) {
                    let mut before = 0u16;
                    for &value in row {
                        bytes.extend_from_slice(&value.wrapping_sub(before).to_le_bytes());
                        before = value;
                    }
                }
                lz4_flex::block::compress_prepend_size(&bytes)
            })
            .collect();
        Self { width, frames }
    }

    /// The frames' raw values as they were kept; `None` if a frame cannot be
    /// restored (which only a fault of memory could cause).
    pub fn frames(&self) -> Option<Vec<Vec<u16>>> {
        self.frames
            .iter()
            .map(|compressed| {
                let bytes = lz4_flex::block::decompress_size_prepended(compressed).ok()?;
                let mut raw = Vec::with_capacity(bytes.len() / 2);
                for row in bytes.chunks(2 * self.width.max(1)) {
                    let mut value = 0u16;
                    for pair in row.chunks_exact(2) {
                        value = value.wrapping_add(u16::from_le_bytes([pair[0], pair[1]]));
                        raw.push(value);
                    }
                }
                Some(raw)
            })
            .collect()
    }

    /// Bytes held.
    pub fn size(&self) -> usize {
        self.frames.iter().map(Vec::len).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_a_frame_exactly() {
        // A tilted floor with noise, no readings in a corner, as a Kinect
        // sees the ground.
        let (width, height) = (640, 480);
        let mut state = 12345u32;
        let raw: Vec<u16> = (0..width * height)
            .map(|k| {
                let (u, v) = (k % width, k / width);
                state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                if u < 40 && v < 30 {
                    2047
                } else {
                    (700 + v / 3 + (state >> 30) as usize) as u16
                }
            })
            .collect();
        let frame = DepthFrame {
            timestamp: 0,
            time_s: 0.0,
            width,
            height,
            raw: raw.clone(),
        };
        let kept = KeptFrames::keep(&[frame.clone(), frame]);
        let back = kept.frames().unwrap();
        assert_eq!(back, vec![raw.clone(), raw]);
        // Two bits of noise a pixel: well under the 1.2 MB of two frames.
        assert!(kept.size() < 2 * 640 * 480, "{} bytes", kept.size());
    }
}
