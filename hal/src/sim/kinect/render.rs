//! Rendering one depth frame: rays from the sensor's true pose into the
//! [`World`], depth to raw values through the depth model ([`Quantiser`]), the
//! noise and the pattern added in disparity, dropouts and the emitter's
//! shadows; each row drawn from its own seeded generator.

use super::*;

/// Depth to raw values: every raw value the model maps to a depth, sorted by
/// depth, with the midpoints in disparity (`1/z`, what the Kinect measures
/// and rounds) between neighbours. The nearest raw of a depth is the one
/// between the midpoints around it: the same answer as
/// [`groundcal_calib::depth::raw_for_depth`], found in constant time.
///
/// Both models are linear in disparity (`1/z` is affine in the raw value), so
/// the midpoints are evenly spaced in `1/z`: a table of bins in `1/z`, finer
/// than a raw step, says where to start looking, and a step or two finds the
/// midpoint.
#[derive(Debug, Clone)]
pub(super) struct Quantiser {
    raws: Vec<u16>,
    depths: Vec<f64>,
    midpoints: Vec<f64>,
    min_depth_m: f64,
    max_depth_m: f64,
    /// The disparity range of the bins, `1/z` in 1/m: from the range's far
    /// end (doubled) to its near end (halved).
    disparity_low: f64,
    disparity_high: f64,
    /// For each bin, from the near end, the index of a midpoint at or below
    /// the nearest depth of the bin.
    bins: Vec<u32>,
}

/// Bins of the quantiser's table: over 0.25–10 m a bin is 0.0005 /m of
/// disparity, a sixth of a raw step in both models (about 0.003 /m). A
/// coarser table would still be exact, only slower.
pub(super) const QUANTISER_BINS: usize = 8192;

impl Quantiser {
    fn new(model: &DepthModel, min_depth_m: f64, max_depth_m: f64) -> Result<Self, SimKinectError> {
        let mut pairs: Vec<(f64, u16)> = (0..RAW_NO_READING)
            .filter_map(|raw| model.depth_m(raw).map(|z| (z, raw)))
            .collect();
        pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
        if pairs.is_empty() {
            return Err(SimKinectError::Config(
                "the depth model maps no raw value to a depth".into(),
            ));
        }
        // Halfway in disparity: 1/m = (1/z₀ + 1/z₁)/2.
        let midpoints: Vec<f64> = pairs
            .windows(2)
            .map(|w| 2.0 * w[0].0 * w[1].0 / (w[0].0 + w[1].0))
            .collect();
        let disparity_low = 0.5 / max_depth_m;
        let disparity_high = 2.0 / min_depth_m;
        let width = (disparity_high - disparity_low) / QUANTISER_BINS as f64;
        let bins = (0..QUANTISER_BINS)
            .map(|b| {
                // The nearest depth of bin b; one midpoint lower for rounding.
                let nearest = 1.0 / (disparity_high - b as f64 * width);
                midpoints
                    .partition_point(|&m| m < nearest)
                    .saturating_sub(1) as u32
            })
            .collect();
        Ok(Self {
            raws: pairs.iter().map(|p| p.1).collect(),
            depths: pairs.iter().map(|p| p.0).collect(),
            midpoints,
            min_depth_m,
            max_depth_m,
            disparity_low,
            disparity_high,
            bins,
        })
    }

    /// The largest depth that quantises to a raw value in the range: the
    /// midpoint past the farthest raw in range (half a raw step, 4 cm at 5 m).
    fn farthest_in_range(&self) -> f64 {
        let last = self.depths.partition_point(|&d| d <= self.max_depth_m);
        last.checked_sub(1)
            .and_then(|i| self.midpoints.get(i))
            .map_or(self.max_depth_m, |&m| m.max(self.max_depth_m))
    }

    /// The raw value nearest `z` in disparity, or "no reading" outside the range.
    fn raw(&self, z: f64) -> u16 {
        let disparity = 1.0 / z;
        // Outside the bins (and for NaN) the nearest raw is out of range: a
        // depth half the range's near end or twice its far end lies many raw
        // steps beyond it.
        if !(disparity > self.disparity_low && disparity <= self.disparity_high) {
            return RAW_NO_READING;
        }
        let bin = ((self.disparity_high - disparity) / (self.disparity_high - self.disparity_low)
            * QUANTISER_BINS as f64) as usize;
        let mut i = self.bins[bin.min(QUANTISER_BINS - 1)] as usize;
        // Ties go to the nearer raw below, as raw_for_depth does.
        while i < self.midpoints.len() && self.midpoints[i] < z {
            i += 1;
        }
        let depth = self.depths[i];
        if depth < self.min_depth_m || depth > self.max_depth_m {
            RAW_NO_READING
        } else {
            self.raws[i]
        }
    }
}

/// Renders raw frames of a world from a sensor pose. Pure and synchronous:
/// the same world, pose and frame number give the same frame.
#[derive(Debug, Clone)]
pub struct DepthRenderer {
    config: SimKinectConfig,
    quantiser: Quantiser,
    /// `(u - cx) / fx` per column: the optical ray's x for a depth of 1.
    ray_x: Vec<f64>,
    /// `(v - cy) / fy` per row: the optical ray's y (down) for a depth of 1.
    ray_y: Vec<f64>,
    /// The distortion per pixel at 1 m in disparity (1/m), row-major; empty
    /// without one.
    distortion: Vec<f64>,
    /// Disparity (1/m) per raw unit: the model's `b` (negative: more raw is
    /// farther).
    disparity_per_raw: f64,
}

impl DepthRenderer {
    /// A renderer for the sensor `config` describes.
    pub fn new(config: &SimKinectConfig) -> Result<Self, SimKinectError> {
        config.validate()?;
        let k = &config.intrinsics;
        Ok(Self {
            config: *config,
            quantiser: Quantiser::new(&config.depth_model, config.min_depth_m, config.max_depth_m)?,
            ray_x: (0..k.width).map(|u| (u as f64 - k.cx) / k.fx).collect(),
            ray_y: (0..k.height).map(|v| (v as f64 - k.cy) / k.fy).collect(),
            distortion: distortion_image(config),
            disparity_per_raw: config.depth_model.inverse_depth_affine().1,
        })
    }

    /// The smooth part of the noise drawn for `index` (a pose's, or a
    /// frame's), raw units, to hand to [`DepthRenderer::render_with`]; None
    /// for noise without one.
    pub fn smooth_noise(&self, key: NoiseKey) -> Option<Vec<f32>> {
        match self.config.noise {
            DepthNoise::Kinect(k) if self.config.noise_scale > 0.0 => Some(k.smooth_field(
                self.config.intrinsics.width,
                self.config.intrinsics.height,
                key,
            )),
            _ => None,
        }
    }

    /// The configuration rendered.
    pub fn config(&self) -> &SimKinectConfig {
        &self.config
    }

    /// The nearest raw value of a depth in metres (2047 outside the range).
    pub fn quantise(&self, z: f64) -> u16 {
        self.quantiser.raw(z)
    }

    /// One raw frame, row-major, top row first, of `world` seen from
    /// `ground_from_sensor`; `frame_index` selects the frame's noise, all of
    /// it drawn for this frame (the smooth part too: [`DepthRenderer::render_with`]
    /// holds it through a pose, as [`SimKinect`] does).
    pub fn render(
        &self,
        world: &World,
        ground_from_sensor: &Transform,
        frame_index: u64,
    ) -> Vec<u16> {
        let smooth = self.smooth_noise(NoiseKey::frame(self.config.seed, frame_index));
        self.render_with(world, ground_from_sensor, frame_index, smooth.as_deref())
    }

    /// [`DepthRenderer::render`] with the smooth part of the noise given
    /// (from [`DepthRenderer::smooth_noise`]); the white part is the frame's.
    ///
    /// Each pixel's ray is the optical `((u-cx)/fx, (v-cy)/fy, 1)`, turned
    /// into G by `ground_from_sensor · sensor_from_optical`: with an optical
    /// z of 1 the ray parameter of the hit is the depth `z` itself.
    pub fn render_with(
        &self,
        world: &World,
        ground_from_sensor: &Transform,
        frame_index: u64,
        smooth: Option<&[f32]>,
    ) -> Vec<u16> {
        let c = &self.config;
        // The noise in disparity (1/m) of a reading at depth z, from its
        // frame's standard normal draw and its pose's smooth part (raw units,
        // more is farther). The former model's white draw enters as
        // `+σ·gaussian` in disparity; the measured one's in raw units.
        let noise = |z: f64, gaussian: f64, smooth_raw: f64| match c.noise {
            DepthNoise::Kinect(k) => {
                self.disparity_per_raw
                    * c.noise_scale
                    * k.gain(z)
                    * (smooth_raw - k.white_raw * gaussian)
            }
            DepthNoise::White { disparity_sigma } => c.noise_scale * disparity_sigma * gaussian,
        };
        let smooth = smooth.filter(|s| s.len() == c.intrinsics.width * c.intrinsics.height);
        let width = c.intrinsics.width;
        let ground_from_optical: Matrix3<f64> =
            ground_from_sensor.rotation.matrix() * sensor_from_optical();
        let (right, down, forward) = (
            ground_from_optical.column(0).into_owned(),
            ground_from_optical.column(1).into_owned(),
            ground_from_optical.column(2).into_owned(),
        );
        let origin = Point3::from(ground_from_sensor.translation.vector);
        // The emitter sits at optical (baseline, 0, 0): sensor Z (right).
        let emitter = ground_from_sensor * Point3::new(0.0, 0.0, c.emitter_baseline_m);
        // Past this depth even 5σ of noise and the whole pattern cannot bring
        // a reading into range.
        let far = self.quantiser.farthest_in_range();
        let pattern_reach = self.distortion.iter().fold(0.0f64, |m, d| m.max(d.abs()));
        let near_enough = 1.0 / far
            - 5.0
                * c.noise_scale
                * c.noise
                    .max_disparity_sigma(c.max_depth_m, self.disparity_per_raw)
            - pattern_reach;
        let t_max = if near_enough > 0.0 {
            1.0 / near_enough
        } else {
            f64::INFINITY
        };
        let live = width - c.dead_columns;
        let shadows = c.emitter_baseline_m > 0.0 && world.has_obstacles();
        // Where each obstacle can be in the image, seen from the camera and
        // from the emitter: rays elsewhere need not ask about it.
        let corners = world.obstacle_corners();
        let in_camera =
            ObstacleBounds::new(&corners, &ground_from_optical, &origin, &c.intrinsics, 0.0);
        let in_emitter = ObstacleBounds::new(
            &corners,
            &ground_from_optical,
            &origin,
            &c.intrinsics,
            c.emitter_baseline_m,
        );
        // A point at depth z seen at column u is at the emitter's column
        // u - fx·baseline/z.
        let emitter_shift = c.intrinsics.fx * c.emitter_baseline_m;

        let mut raw = vec![RAW_NO_READING; width * c.intrinsics.height];
        raw.par_chunks_mut(width).enumerate().for_each(|(v, row)| {
            let mut rng = row_rng(c.seed, frame_index, v);
            let row_direction = forward + down * self.ray_y[v];
            let (camera_row, emitter_row) = (in_camera.row(v as f64), in_emitter.row(v as f64));
            let mut spare = None;
            let mut ground_height = None;
            for (u, value) in row.iter_mut().enumerate().take(live) {
                // A fixed number of draws per pixel: a pixel's noise does
                // not depend on what its neighbours saw.
                let gaussian = spare.take().unwrap_or_else(|| {
                    let (a, b) = normal_pair(&mut rng);
                    spare = Some(b);
                    a
                });
                let chance: f64 = rng.gen();
                let direction = row_direction + right * self.ray_x[u];
                let hints = RayHints {
                    candidates: ObstacleBounds::candidates(&camera_row, u as f64),
                    ground_height,
                };
                let Some(hit) = world.cast_with(&origin, &direction, t_max, &hints) else {
                    continue;
                };
                if hit.surface == Surface::Ground {
                    ground_height = Some(origin.y + direction.y * hit.t);
                }
                let z = hit.t;
                // The noise is in disparity, as the Kinect's correlation
                // measures it (raw units, more is farther): the frame's
                // white part and the pose's smooth part, grown with depth.
                let smooth_raw = smooth.map_or(0.0, |s| f64::from(s[v * width + u]));
                let mut disparity = 1.0 / (z * c.depth_scale) + noise(z, gaussian, smooth_raw);
                if let Some(pattern) = self.distortion.get(v * width + u) {
                    disparity += pattern * (-c.distortion.decay_per_m * (z - 1.0)).exp();
                }
                if disparity <= 0.0 {
                    continue;
                }
                let quantised = self.quantiser.raw(1.0 / disparity);
                if quantised == RAW_NO_READING {
                    continue;
                }
                let cos_incidence = hit.normal.dot(&direction).abs() / direction.norm();
                let grazing = ((GRAZING_COS - cos_incidence) / GRAZING_COS).clamp(0.0, 1.0);
                if chance < c.dropout_rate + c.grazing_dropout * grazing {
                    continue;
                }
                let candidates =
                    ObstacleBounds::candidates(&emitter_row, u as f64 - emitter_shift / z);
                if shadows && candidates != 0 {
                    let lit = origin + direction * z;
                    let towards = lit - emitter;
                    let reach = 1.0 - SHADOW_TOLERANCE_M / towards.norm();
                    if world.blocked_by_obstacle_among(&emitter, &towards, reach, candidates) {
                        continue;
                    }
                }
                *value = quantised;
            }
        });
        raw
    }
}

/// The distortion of every pixel at 1 m in disparity, 1/m (row-major), or
/// nothing without one: `b` raw units per 1/m (the model's inverse depth is
/// `a + b·raw`).
pub(super) fn distortion_image(config: &SimKinectConfig) -> Vec<f64> {
    if config.distortion.shape == DistortionShape::None || config.distortion.amplitude_raw == 0.0 {
        return Vec::new();
    }
    let (_, b) = config.depth_model.inverse_depth_affine();
    let k = &config.intrinsics;
    if let DistortionShape::Measured { plane } = config.distortion.shape {
        return measured_pattern(
            k.width,
            k.height,
            config.seed,
            config.distortion.amplitude_raw,
            plane,
        )
        .into_iter()
        .map(|raw| b * f64::from(raw))
        .collect();
    }
    (0..k.height)
        .flat_map(|v| (0..k.width).map(move |u| (u, v)))
        .map(|(u, v)| b * config.distortion.raw_at(u as f64, v as f64, k))
        .collect()
}

/// The pixel rectangles that hold each obstacle's image, as seen by a
/// pinhole at the camera or at the emitter (the camera's intrinsics, shifted
/// along the optical x axis): a ray outside an obstacle's rectangle cannot
/// meet it. An obstacle with a corner behind the pinhole gets no rectangle
/// and is asked by every ray.
pub(super) struct ObstacleBounds {
    /// `[u_lo, u_hi, v_lo, v_hi]` per obstacle, a pixel wider on every side.
    rectangles: Vec<[f64; 4]>,
}

impl ObstacleBounds {
    fn new(
        corners: &[Vec<Point3<f64>>],
        ground_from_optical: &Matrix3<f64>,
        camera: &Point3<f64>,
        intrinsics: &Intrinsics,
        x_offset: f64,
    ) -> Self {
        let everywhere = [
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
        ];
        let rectangles = corners
            .iter()
            .map(|obstacle| {
                let mut r = [
                    f64::INFINITY,
                    f64::NEG_INFINITY,
                    f64::INFINITY,
                    f64::NEG_INFINITY,
                ];
                for corner in obstacle {
                    let p = ground_from_optical.transpose() * (corner - camera);
                    if p.z <= 1e-6 {
                        return everywhere;
                    }
                    let u = intrinsics.fx * (p.x - x_offset) / p.z + intrinsics.cx;
                    let v = intrinsics.fy * p.y / p.z + intrinsics.cy;
                    r = [
                        r[0].min(u - 1.0),
                        r[1].max(u + 1.0),
                        r[2].min(v - 1.0),
                        r[3].max(v + 1.0),
                    ];
                }
                r
            })
            .collect();
        Self { rectangles }
    }

    /// The obstacles (index, u_lo, u_hi) whose rectangles hold row `v`;
    /// those from the 65th on are always there.
    fn row(&self, v: f64) -> Vec<(usize, f64, f64)> {
        self.rectangles
            .iter()
            .enumerate()
            .filter(|(i, r)| *i >= 64 || (r[2]..=r[3]).contains(&v))
            .map(|(i, r)| (i, r[0], r[1]))
            .collect()
    }

    /// The bits of the row's obstacles whose rectangles hold column `u`.
    fn candidates(row: &[(usize, f64, f64)], u: f64) -> u64 {
        row.iter()
            .filter(|&&(i, lo, hi)| i < 64 && (lo..=hi).contains(&u))
            .fold(0, |mask, &(i, _, _)| mask | 1 << i)
    }
}

/// The generator of one row of one frame: keyed by all three so that rows
/// can be drawn in any order on any thread.
pub(super) fn row_rng(seed: u64, frame_index: u64, row: usize) -> ChaCha8Rng {
    let mut key = [0u8; 32];
    key[..8].copy_from_slice(&seed.to_le_bytes());
    key[8..16].copy_from_slice(&frame_index.to_le_bytes());
    key[16..24].copy_from_slice(&(row as u64).to_le_bytes());
    key[24..].copy_from_slice(b"simkinct");
    ChaCha8Rng::from_seed(key)
}

/// Two independent standard normal deviates (Box–Muller).
pub(super) fn normal_pair(rng: &mut impl Rng) -> (f64, f64) {
    let u1: f64 = 1.0 - rng.gen::<f64>();
    let u2: f64 = rng.gen();
    let radius = (-2.0 * u1.ln()).sqrt();
    let (s, c) = (std::f64::consts::TAU * u2).sin_cos();
    (radius * c, radius * s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use groundcal_calib::depth::raw_for_depth;

    #[test]
    fn quantiser_agrees_with_raw_for_depth() {
        for model in [DepthModel::default(), DepthModel::inverse_linear_default()] {
            let q = Quantiser::new(&model, 0.5, 5.0).unwrap();
            let mut rng = ChaCha8Rng::seed_from_u64(9);
            for _ in 0..5000 {
                let z = rng.gen_range(0.3..6.0);
                let expected = raw_for_depth(&model, z)
                    .filter(|&r| (0.5..=5.0).contains(&model.depth_m(r).unwrap()))
                    .unwrap_or(RAW_NO_READING);
                assert_eq!(q.raw(z), expected, "z = {z}");
            }
            assert_eq!(q.raw(f64::NAN), RAW_NO_READING);
            assert_eq!(q.raw(-1.0), RAW_NO_READING);
        }
    }

    #[test]
    fn standard_normal_has_unit_variance() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let n = 200_000;
        let samples: Vec<f64> = (0..n / 2)
            .flat_map(|_| {
                let (a, b) = normal_pair(&mut rng);
                [a, b]
            })
            .collect();
        let mean = samples.iter().sum::<f64>() / n as f64;
        let var = samples.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        assert!(
            mean.abs() < 0.01 && (var - 1.0).abs() < 0.01,
            "{mean} {var}"
        );
    }
}
