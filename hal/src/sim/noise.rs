//! The simulated Kinect's depth noise and fixed pattern, in raw units of
//! disparity (positive is farther), as measured on real Kinect v1 frames of
//! a floor (TUM RGB-D fr3 cabinet, 58 frames; PCL's tilted floor; TUM's
//! office): docs/method.md, "The Kinect's noise as measured", and
//! `tests/real_noise.rs`, which computes the same statistics on the real
//! frames and on these.
//!
//! A real Kinect's error is not independent from pixel to pixel. Its floor
//! residual is correlated at 0.92 one pixel apart and still 0.46 at 32
//! pixels; an 8 × 8 cell's mean varies 46 times more than independent pixels
//! would make it. About 60 % of that variance is a pattern fixed in the
//! image, the same at every pose; the rest is drawn afresh with the view:
//!
//! - [`KinectNoise`]: a white part (0.07 raw, each frame), and three
//!   smooth parts, short (a 4 × 3 box applied twice, 0.33 raw), medium (a
//!   15-pixel box, 0.15 raw) and long (a 200-pixel box, 0.29 raw), growing
//!   beyond 1.75 m by 45 % a metre. The smooth parts are the speckle's
//!   error on the scene as seen: they hold while the sensor holds still and
//!   are drawn afresh for every pose ([`NoiseHeld::PerPose`]), so averaging
//!   a pose's frames does not take them out.
//! - [`measured_pattern`]: a device's fixed pattern, a smooth field of
//!   0.80 raw RMS (a 199-pixel triangle kernel), 42-pixel sawtooth stripes
//!   down the image (0.20 raw) and a fine texture (0.15 raw), with the plane
//!   part its smooth field carries (about 0.2 raw and 0.0013 raw a pixel),
//!   which no frame of a floor can tell from a turn of the sensor.
//!
//! Every part is drawn from ChaCha generators keyed by the seed and what the
//! part belongs to (the pose, the frame, the device), row by row, so that
//! the same keys give the same noise on any number of threads. Box sums are
//! running sums along each axis (a summed-area table, separably).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// The measured noise of a Kinect v1, raw units (module documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KinectNoise {
    /// Independent per pixel and frame.
    pub white_raw: f64,
    /// A 4 (across) × 3 (down) box applied twice: a 7 × 5 triangle kernel.
    pub short_raw: f64,
    /// A 15 × 15 box.
    pub medium_raw: f64,
    /// A 200 × 200 box: a smooth warp of the whole view.
    pub long_raw: f64,
    /// Beyond this depth the noise grows…
    pub gain_from_m: f64,
    /// …by this share a metre.
    pub gain_per_m: f64,
    /// Whether the smooth parts hold while the sensor holds still.
    pub held: NoiseHeld,
}

/// When the smooth parts of [`KinectNoise`] are drawn afresh.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum NoiseHeld {
    /// Once a pose: the speckle's error belongs to the scene as seen, which
    /// does not change while the sensor holds still (the pessimistic and,
    /// for a still scene, the physical choice: a pose's frames then share it).
    #[default]
    PerPose,
    /// Every frame, as the measured sequence (a moving camera) drew them.
    PerFrame,
}

impl Default for KinectNoise {
    /// As measured (docs/method.md): σ 0.47 raw before quantisation to 1.75 m.
    fn default() -> Self {
        Self {
            white_raw: 0.07,
            short_raw: 0.33,
            medium_raw: 0.149,
            long_raw: 0.287,
            gain_from_m: 1.75,
            gain_per_m: 0.45,
            held: NoiseHeld::PerPose,
        }
    }
}

impl KinectNoise {
    /// σ of the smooth parts together, raw units (before the depth gain).
    pub fn smooth_sigma_raw(&self) -> f64 {
        (self.short_raw.powi(2) + self.medium_raw.powi(2) + self.long_raw.powi(2)).sqrt()
    }

    /// The noise's growth at depth `z` (metres): 1 up to `gain_from_m`.
    pub fn gain(&self, z: f64) -> f64 {
        1.0 + self.gain_per_m * (z - self.gain_from_m).max(0.0)
    }

    /// Whether every setting is usable.
    pub fn validate(&self) -> Result<(), String> {
        for (name, value) in [
            ("white_raw", self.white_raw),
            ("short_raw", self.short_raw),
            ("medium_raw", self.medium_raw),
            ("long_raw", self.long_raw),
            ("gain_per_m", self.gain_per_m),
        ] {
            if !(value.is_finite() && (0.0..=10.0).contains(&value)) {
                return Err(format!(
                    "the noise's {name} must lie in [0, 10], not {value}"
                ));
            }
        }
        if !(self.gain_from_m.is_finite() && self.gain_from_m >= 0.0) {
            return Err(format!(
                "the noise's gain_from_m must be a depth ≥ 0, not {}",
                self.gain_from_m
            ));
        }
        Ok(())
    }

    /// The smooth parts over a `width` × `height` image, raw units (before
    /// the depth gain), drawn from `key` (the seed and the pose or frame).
    pub fn smooth_field(&self, width: usize, height: usize, key: NoiseKey) -> Vec<f32> {
        let mut field = vec![0f32; width * height];
        for (part, sigma, (kw, kh), twice) in [
            (1u64, self.short_raw, (4, 3), true),
            (2, self.medium_raw, (15, 15), false),
            (3, self.long_raw, (200, 200), false),
        ] {
            if sigma == 0.0 {
                continue;
            }
            let unit = box_field(width, height, kw, kh, twice, key.part(part));
            for (f, u) in field.iter_mut().zip(&unit) {
                *f += (sigma as f32) * u;
            }
        }
        field
    }
}

/// What a draw of noise belongs to: the seed, a kind, and an index (the
/// pose, the frame, the device), and the part drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NoiseKey {
    pub seed: u64,
    pub index: u64,
    pub part: u64,
}

impl NoiseKey {
    /// The key of a pose's smooth noise.
    pub fn pose(seed: u64, pose: u64) -> Self {
        Self {
            seed,
            index: pose,
            part: 0x706f_7365,
        }
    }

    /// The key of a frame's own smooth noise ([`NoiseHeld::PerFrame`]).
    pub fn frame(seed: u64, frame: u64) -> Self {
        Self {
            seed,
            index: frame,
            part: 0x6672_616d,
        }
    }

    /// The key of a device's fixed pattern.
    pub fn device(seed: u64) -> Self {
        Self {
            seed,
            index: 0,
            part: 0x6465_7669,
        }
    }

    fn part(self, part: u64) -> Self {
        Self {
            part: self.part.wrapping_mul(31).wrapping_add(part),
            ..self
        }
    }

    /// The generator of one row of this draw.
    fn row(self, row: usize) -> ChaCha8Rng {
        let mut key = [0u8; 32];
        key[..8].copy_from_slice(&self.seed.to_le_bytes());
        key[8..16].copy_from_slice(&self.index.to_le_bytes());
        key[16..24].copy_from_slice(&self.part.to_le_bytes());
        key[24..].copy_from_slice(&(row as u64).to_le_bytes());
        ChaCha8Rng::from_seed(key)
    }
}

/// Standard normal deviates for a `width` × `height` image, row by row.
fn normals(width: usize, height: usize, key: NoiseKey) -> Vec<f32> {
    let mut out = vec![0f32; width * height];
    out.par_chunks_mut(width.max(1))
        .enumerate()
        .for_each(|(row, values)| {
            let mut rng = key.row(row);
            let mut k = 0;
            while k < values.len() {
                let (a, b) = normal_pair(&mut rng);
                values[k] = a as f32;
                if k + 1 < values.len() {
                    values[k + 1] = b as f32;
                }
                k += 2;
            }
        });
    out
}

/// Two independent standard normal deviates (Box–Muller).
fn normal_pair(rng: &mut impl Rng) -> (f64, f64) {
    let u1: f64 = 1.0 - rng.gen::<f64>();
    let u2: f64 = rng.gen();
    let radius = (-2.0 * u1.ln()).sqrt();
    let (s, c) = (std::f64::consts::TAU * u2).sin_cos();
    (radius * c, radius * s)
}

/// Sums over windows of `k` along each row of a `width`-wide image:
/// `width − k + 1` sums a row.
fn box_rows(image: &[f32], width: usize, k: usize) -> Vec<f32> {
    let out_width = width + 1 - k;
    let rows = image.len() / width;
    let mut out = vec![0f32; out_width * rows];
    out.par_chunks_mut(out_width)
        .zip(image.par_chunks(width))
        .for_each(|(out, row)| {
            // Running sums in f64: no drift over 800 pixels.
            let mut sum: f64 = row[..k].iter().map(|&v| f64::from(v)).sum();
            out[0] = sum as f32;
            for u in 1..out_width {
                sum += f64::from(row[u + k - 1]) - f64::from(row[u - 1]);
                out[u] = sum as f32;
            }
        });
    out
}

/// The transpose of a `width`-wide image.
fn transpose(image: &[f32], width: usize) -> Vec<f32> {
    let height = image.len() / width;
    let mut out = vec![0f32; image.len()];
    for v in 0..height {
        for u in 0..width {
            out[u * height + v] = image[v * width + u];
        }
    }
    out
}

/// Box sums of `kw` across and `kh` down: a `(w − kw + 1) × (h − kh + 1)` image.
fn box_sums(image: &[f32], width: usize, kw: usize, kh: usize) -> (Vec<f32>, usize) {
    let across = box_rows(image, width, kw);
    let w1 = width + 1 - kw;
    let height = image.len() / width;
    let down = box_rows(&transpose(&across, w1), height, kh);
    (transpose(&down, height + 1 - kh), w1)
}

/// A field of unit σ over `width` × `height` whose autocorrelation is the
/// box's triangle `(1 − |du|/kw)(1 − |dv|/kh)` (or, applied twice, the
/// triangle's own autocorrelation): white noise on a grid larger by the
/// kernel, box-summed, divided by the kernel's root sum of squares.
pub fn box_field(
    width: usize,
    height: usize,
    kw: usize,
    kh: usize,
    twice: bool,
    key: NoiseKey,
) -> Vec<f32> {
    let passes = if twice { 2 } else { 1 };
    let (gw, gh) = (width + passes * (kw - 1), height + passes * (kh - 1));
    let mut image = normals(gw, gh, key);
    let mut w = gw;
    for _ in 0..passes {
        let (next, next_w) = box_sums(&image, w, kw, kh);
        image = next;
        w = next_w;
    }
    // Σ of the squared kernel: k for a box, (2k³ + k)/3 for a box twice.
    let squares = |k: usize| {
        let k = k as f64;
        if twice {
            (2.0 * k * k * k + k) / 3.0
        } else {
            k
        }
    };
    let scale = (1.0 / (squares(kw) * squares(kh)).sqrt()) as f32;
    image.iter_mut().for_each(|v| *v *= scale);
    image
}

/// The measured device's fixed pattern (module documentation), raw units,
/// row-major, scaled so that its smooth field's RMS (its plane part left
/// out) is `smooth_rms_raw` (0.80 measured; the stripes and texture scale
/// with it). `plane` adds (or, with `false`, leaves out) the plane part the
/// smooth field carries.
pub fn measured_pattern(
    width: usize,
    height: usize,
    seed: u64,
    smooth_rms_raw: f64,
    plane: bool,
) -> Vec<f32> {
    let key = NoiseKey::device(seed);
    let scale = smooth_rms_raw / 0.80;
    // 1. A smooth field: a 100-pixel box twice along each axis.
    let smooth = box_field(width, height, 100, 100, true, key.part(1));
    let fit = least_squares_plane(&smooth, width);
    let without_plane: Vec<f64> = smooth
        .iter()
        .enumerate()
        .map(|(k, &v)| f64::from(v) - fit.at(k % width, k / width))
        .collect();
    let rms = (without_plane.iter().map(|v| v * v).sum::<f64>() / without_plane.len() as f64)
        .sqrt()
        .max(f64::MIN_POSITIVE);
    let gain = smooth_rms_raw / rms;
    // 2. Sawtooth stripes down the image, 42 pixels apart, a random phase.
    let phase: f64 = key.part(2).row(0).gen::<f64>() * 42.0;
    let stripes: Vec<f64> = (0..width)
        .map(|u| {
            let x = ((u as f64 + phase) / 42.0).fract();
            0.20 * scale * 12f64.sqrt() * (0.5 - x)
        })
        .collect();
    // 3. A fine texture: a 3-pixel box.
    let fine = box_field(width, height, 3, 3, false, key.part(3));
    let mut pattern: Vec<f64> = (0..width * height)
        .map(|k| without_plane[k] * gain + stripes[k % width] + 0.15 * scale * f64::from(fine[k]))
        .collect();
    // Stripes and texture carry no plane of their own: only the smooth
    // field's, which stays (or goes) as asked.
    let rest = least_squares_plane_f64(&pattern, width);
    for (k, value) in pattern.iter_mut().enumerate() {
        let (u, v) = (k % width, k / width);
        *value -= rest.at(u, v);
        if plane {
            *value += gain * fit.at(u, v);
        }
    }
    pattern.into_iter().map(|v| v as f32).collect()
}

/// A plane `c0 + cu·u + cv·v` over an image's pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
struct PixelPlaneFit {
    c0: f64,
    cu: f64,
    cv: f64,
}

impl PixelPlaneFit {
    fn at(&self, u: usize, v: usize) -> f64 {
        self.c0 + self.cu * u as f64 + self.cv * v as f64
    }
}

fn least_squares_plane(image: &[f32], width: usize) -> PixelPlaneFit {
    let values: Vec<f64> = image.iter().map(|&v| f64::from(v)).collect();
    least_squares_plane_f64(&values, width)
}

/// The least-squares plane of a full image (its pixels on a grid: the
/// normal equations in closed form, about the image's centre).
fn least_squares_plane_f64(image: &[f64], width: usize) -> PixelPlaneFit {
    let height = image.len() / width;
    let (cu0, cv0) = ((width as f64 - 1.0) / 2.0, (height as f64 - 1.0) / 2.0);
    let (mut s, mut su, mut sv, mut uu, mut vv) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (k, &value) in image.iter().enumerate() {
        let (u, v) = ((k % width) as f64 - cu0, (k / width) as f64 - cv0);
        s += value;
        su += value * u;
        sv += value * v;
        uu += u * u;
        vv += v * v;
    }
    let n = image.len() as f64;
    let (cu, cv) = (su / uu, sv / vv);
    PixelPlaneFit {
        c0: s / n - cu * cu0 - cv * cv0,
        cu,
        cv,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stats(field: &[f32]) -> (f64, f64) {
        let n = field.len() as f64;
        let mean = field.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
        let var = field
            .iter()
            .map(|&v| (f64::from(v) - mean).powi(2))
            .sum::<f64>()
            / n;
        (mean, var.sqrt())
    }

    /// A correlation along rows at `lag`.
    fn lag_correlation(field: &[f32], width: usize, lag: usize) -> f64 {
        let (mean, sigma) = stats(field);
        let (mut sum, mut count) = (0.0, 0.0);
        for row in field.chunks(width) {
            for u in 0..width - lag {
                sum += (f64::from(row[u]) - mean) * (f64::from(row[u + lag]) - mean);
                count += 1.0;
            }
        }
        sum / count / (sigma * sigma)
    }

    /// Each box field has unit σ and its box's triangle correlation.
    #[test]
    fn box_fields_have_unit_sigma_and_their_kernels_correlation() {
        let key = NoiseKey::pose(7, 3);
        let field = box_field(640, 480, 15, 15, false, key);
        let (mean, sigma) = stats(&field);
        assert!(
            mean.abs() < 0.1 && (sigma - 1.0).abs() < 0.1,
            "{mean} {sigma}"
        );
        // (1 − 5/15) = 0.667 at a lag of 5 pixels.
        let rho = lag_correlation(&field, 640, 5);
        assert!((rho - 2.0 / 3.0).abs() < 0.05, "{rho}");
        let twice = box_field(640, 480, 4, 3, true, key);
        let (_, sigma) = stats(&twice);
        assert!((sigma - 1.0).abs() < 0.05, "{sigma}");
        // A 4-box twice is the triangle 1,2,3,4,3,2,1: against itself two
        // pixels on, 31 of its 44.
        let rho = lag_correlation(&twice, 640, 2);
        assert!((rho - 31.0 / 44.0).abs() < 0.05, "{rho}");
        // The same key, the same field; another, another.
        assert_eq!(field, box_field(640, 480, 15, 15, false, key));
        assert_ne!(
            field,
            box_field(640, 480, 15, 15, false, NoiseKey::pose(7, 4))
        );
    }

    /// The measured pattern: 0.8 raw RMS and more, its plane part as asked.
    #[test]
    fn the_measured_pattern_has_its_size_and_its_plane_part_as_asked() {
        let flat = measured_pattern(640, 480, 7, 0.8, false);
        let (_, sigma) = stats(&flat);
        assert!((0.8..0.95).contains(&sigma), "{sigma}");
        let plane = least_squares_plane(&flat, 640);
        assert!(plane.cu.abs() < 1e-6 && plane.cv.abs() < 1e-6 && plane.at(320, 240).abs() < 1e-4);
        let with = measured_pattern(640, 480, 7, 0.8, true);
        let plane = least_squares_plane(&with, 640);
        assert!(plane.cu != 0.0 && plane.cv != 0.0);
        assert_ne!(flat, measured_pattern(640, 480, 8, 0.8, false));
    }
}
