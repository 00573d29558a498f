//! The simulated Kinect's noise against a real Kinect's (issue 41): the same
//! statistics of the floor's residual on real Kinect v1 frames and on the
//! simulator's frames of the same floors, through the same measurement.
//!
//! Real: the 58 frames of TUM RGB-D fr3 cabinet (`../shared/data/real/
//! tum-fr3-cabinet/`, one Kinect, a floor seen from 0.9–1.3 m). Each frame's
//! floor is found with groundcal's own ground fit, refined by least squares
//! in inverse depth within a band about it (objects on the floor left out
//! by a 15-pixel mean of the residual), and its residual taken in raw units
//! (`(1/z − 1/z_plane)/b`, more is farther). Simulated: for every fourth real
//! frame, the simulator's flat floor rendered from a sensor at that frame's
//! plane, with that frame's floor mask, measured the same way; the frames
//! share one simulated device (its fixed pattern) and each draws its own
//! noise, as the real frames come from a camera that moves.
//!
//! The split of the two: the residual averaged per 16-pixel cell over the
//! floors is the fixed pattern (real 0.83 raw RMS), and what is left of each
//! floor is its noise, with its own autocorrelation and cell ratios; the
//! simulator must match the pattern within a factor of 1.25 and the noise
//! within ±0.15 and a factor of 1.5. (Of the real noise's long-range part,
//! 10-cm squares of the floor carry 0.16 raw RMS that two random halves of
//! the frames agree on, correlation 0.73–0.81: the floor's own relief,
//! about 1.2 mm, which the simulator counts as noise.)
//!
//! The statistics: the residual's autocorrelation at 1, 2, 4, 8, 16 and 32
//! pixels across and down, and the cell-mean variance ratio of 8- and
//! 16-pixel cells (`var(cell means) / (var(pixels)/n)`: 1 for independent
//! pixels). The simulator must match the real mean within ±0.1 at each lag
//! and within a factor of 1.5 for each ratio. Independent pixels (the
//! former model) give ratios of about 1 and correlations near 0 beyond a
//! pixel, and fail.

mod common;

use groundcal::calib::geometry::{sensor_from_optical, Transform};
use groundcal::calib::sensor::{DepthModel, Intrinsics};
use groundcal::cli::plane::{fit_file, to_optical, PlaneOptions};
use groundcal::formats::depth_image::{read_depth_image, DepthUnits};
use groundcal_hal::sim::kinect::{DepthNoise, DepthRenderer, SimKinectConfig};
use groundcal_hal::sim::world::World;
use nalgebra::{Matrix3, Rotation3, Translation3, Vector3};

/// Disparity (1/m) per raw unit of the inverse-linear model (more is farther).
const B: f64 = -0.003_071_1;
const LAGS: [usize; 6] = [1, 2, 4, 8, 16, 32];

/// TUM's freiburg3 intrinsics.
fn fr3() -> Intrinsics {
    Intrinsics {
        fx: 535.4,
        fy: 539.2,
        cx: 320.1,
        cy: 247.6,
        width: 640,
        height: 480,
    }
}

/// A plane of inverse depth over the pixels: `w = c0 + cu·u + cv·v`.
#[derive(Debug, Clone, Copy)]
struct PixelPlane {
    c0: f64,
    cu: f64,
    cv: f64,
}

impl PixelPlane {
    fn at(&self, u: usize, v: usize) -> f64 {
        self.c0 + self.cu * u as f64 + self.cv * v as f64
    }
}

/// The least-squares plane of `w` over the pixels `mask` takes.
fn fit(w: &[f64], mask: &[bool], width: usize) -> PixelPlane {
    let (mut m, mut r) = (Matrix3::<f64>::zeros(), Vector3::<f64>::zeros());
    for (k, (&w, &m_k)) in w.iter().zip(mask).enumerate() {
        if m_k {
            let phi = Vector3::new(1.0, (k % width) as f64, (k / width) as f64);
            m += phi * phi.transpose();
            r += phi * w;
        }
    }
    let c = m.try_inverse().expect("a floor of many pixels") * r;
    PixelPlane {
        c0: c.x,
        cu: c.y,
        cv: c.z,
    }
}

/// A floor: inverse depth per pixel (0: none), the pixels taken, the plane.
struct Floor {
    w: Vec<f64>,
    mask: Vec<bool>,
    plane: PixelPlane,
}

impl Floor {
    /// The residual in raw units, 0 off the floor.
    fn residual(&self, width: usize) -> Vec<f64> {
        self.w
            .iter()
            .zip(&self.mask)
            .enumerate()
            .map(|(k, (&w, &m))| {
                if m {
                    (w - self.plane.at(k % width, k / width)) / B
                } else {
                    0.0
                }
            })
            .collect()
    }
}

/// Refines a floor from a first plane: least squares within a band (four
/// robust σ, at least 1.5 raw units) for a few rounds, then leaves out what
/// lies on the floor (a 15-pixel mean of the residual beyond 3 raw units)
/// and fits once more.
fn refine(w: Vec<f64>, start: PixelPlane, width: usize) -> Floor {
    let mut plane = start;
    let mut mask = vec![false; w.len()];
    for _ in 0..8 {
        let residual: Vec<f64> = w
            .iter()
            .enumerate()
            .map(|(k, &w)| (w - plane.at(k % width, k / width)) / B)
            .collect();
        let mut near: Vec<f64> = residual
            .iter()
            .zip(&w)
            .filter(|(r, &w)| w > 0.0 && r.abs() < 6.0)
            .map(|(r, _)| r.abs())
            .collect();
        near.sort_by(f64::total_cmp);
        let mad = near.get(near.len() / 2).copied().unwrap_or(1.0);
        let band = (4.0 * 1.4826 * mad).max(1.5);
        for (k, m) in mask.iter_mut().enumerate() {
            *m = w[k] > 0.0 && residual[k].abs() < band;
        }
        plane = fit(&w, &mask, width);
    }
    let floor = Floor { w, mask, plane };
    let residual = floor.residual(width);
    let local = box_mean(&residual, &floor.mask, width, 7);
    let mask: Vec<bool> = floor
        .mask
        .iter()
        .zip(&local)
        .map(|(&m, &l)| m && l.abs() < 3.0)
        .collect();
    let plane = fit(&floor.w, &mask, width);
    Floor {
        w: floor.w,
        mask,
        plane,
    }
}

/// The mean of `values` over the pixels `mask` takes within `radius` of each.
fn box_mean(values: &[f64], mask: &[bool], width: usize, radius: usize) -> Vec<f64> {
    let height = values.len() / width;
    // Summed-area tables of the values and of the count.
    let mut sum = vec![0.0; (width + 1) * (height + 1)];
    let mut count = vec![0.0; (width + 1) * (height + 1)];
    for v in 0..height {
        for u in 0..width {
            let k = v * width + u;
            let (s, c) = if mask[k] {
                (values[k], 1.0)
            } else {
                (0.0, 0.0)
            };
            let i = (v + 1) * (width + 1) + u + 1;
            sum[i] = s + sum[i - 1] + sum[i - width - 1] - sum[i - width - 2];
            count[i] = c + count[i - 1] + count[i - width - 1] - count[i - width - 2];
        }
    }
    let at = |t: &[f64], u: usize, v: usize| t[v * (width + 1) + u];
    (0..width * height)
        .map(|k| {
            let (u, v) = (k % width, k / width);
            let (u0, v0) = (u.saturating_sub(radius), v.saturating_sub(radius));
            let (u1, v1) = ((u + radius + 1).min(width), (v + radius + 1).min(height));
            let box_of = |t: &[f64]| at(t, u1, v1) - at(t, u0, v1) - at(t, u1, v0) + at(t, u0, v0);
            let n = box_of(&count);
            if n > 0.0 {
                box_of(&sum) / n
            } else {
                0.0
            }
        })
        .collect()
}

/// The statistics of one floor's residual.
#[derive(Debug, Clone, Default)]
struct Stats {
    across: [f64; 6],
    down: [f64; 6],
    ratio8: f64,
    ratio16: f64,
}

fn stats(floor: &Floor, width: usize) -> Stats {
    residual_stats(&floor.residual(width), &floor.mask, width)
}

/// The statistics of a residual `r` over the pixels `m` takes.
fn residual_stats(r: &[f64], m: &[bool], width: usize) -> Stats {
    let height = r.len() / width;
    let n = m.iter().filter(|&&m| m).count() as f64;
    let mean = r
        .iter()
        .zip(m)
        .filter(|(_, &m)| m)
        .map(|(r, _)| r)
        .sum::<f64>()
        / n;
    let var = r
        .iter()
        .zip(m)
        .filter(|(_, &m)| m)
        .map(|(r, _)| (r - mean).powi(2))
        .sum::<f64>()
        / n;
    let correlation = |du: usize, dv: usize| {
        let (mut s, mut c) = (0.0, 0.0);
        for v in 0..height - dv {
            for u in 0..width - du {
                let (a, b) = (v * width + u, (v + dv) * width + u + du);
                if m[a] && m[b] {
                    s += (r[a] - mean) * (r[b] - mean);
                    c += 1.0;
                }
            }
        }
        s / c / var
    };
    let ratio = |cell: usize| {
        let (mut means, mut counts) = (Vec::new(), Vec::new());
        for cv in 0..height / cell {
            for cu in 0..width / cell {
                let (mut s, mut c) = (0.0, 0.0);
                for v in cv * cell..(cv + 1) * cell {
                    for u in cu * cell..(cu + 1) * cell {
                        if m[v * width + u] {
                            s += r[v * width + u] - mean;
                            c += 1.0;
                        }
                    }
                }
                if c >= 0.75 * (cell * cell) as f64 {
                    means.push(s / c);
                    counts.push(c);
                }
            }
        }
        let k = means.len() as f64;
        let grand = means.iter().sum::<f64>() / k;
        let spread = means.iter().map(|x| (x - grand).powi(2)).sum::<f64>() / (k - 1.0);
        let harmonic = k / counts.iter().map(|c| 1.0 / c).sum::<f64>();
        spread / (var / harmonic)
    };
    Stats {
        across: LAGS.map(|l| correlation(l, 0)),
        down: LAGS.map(|l| correlation(0, l)),
        ratio8: ratio(8),
        ratio16: ratio(16),
    }
}

/// The side of the cells in which the fixed pattern is taken apart from the noise.
const PATTERN_CELL: usize = 16;

/// What is fixed in the image and what is not: the residual averaged per
/// 16-pixel cell over the floors (the pattern map, its RMS over the cells
/// seen in at least three floors' worth), and every floor's residual less
/// that map (the noise of a frame, with what of the pattern is finer than a
/// cell). The real sequence's camera moves, so the floor under a cell
/// changes and what stays is the sensor's.
fn pattern_and_noise(floors: &[&Floor], width: usize) -> (f64, Stats) {
    let height = floors[0].mask.len() / width;
    let (cells_u, cells_v) = (width / PATTERN_CELL, height / PATTERN_CELL);
    let cell = |k: usize| {
        let (u, v) = (k % width / PATTERN_CELL, k / width / PATTERN_CELL);
        (u < cells_u && v < cells_v).then_some(v * cells_u + u)
    };
    let (mut sum, mut count) = (vec![0.0; cells_u * cells_v], vec![0.0; cells_u * cells_v]);
    let residuals: Vec<Vec<f64>> = floors.iter().map(|f| f.residual(width)).collect();
    for (floor, r) in floors.iter().zip(&residuals) {
        for (k, &m) in floor.mask.iter().enumerate() {
            if let (true, Some(c)) = (m, cell(k)) {
                sum[c] += r[k];
                count[c] += 1.0;
            }
        }
    }
    let enough = 3.0 * (PATTERN_CELL * PATTERN_CELL) as f64;
    let map: Vec<Option<f64>> = sum
        .iter()
        .zip(&count)
        .map(|(&s, &c)| (c >= enough).then(|| s / c))
        .collect();
    let seen: Vec<f64> = map.iter().flatten().copied().collect();
    let mean = seen.iter().sum::<f64>() / seen.len() as f64;
    let rms = (seen.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / seen.len() as f64).sqrt();
    let noise: Vec<Stats> = floors
        .iter()
        .zip(&residuals)
        .map(|(floor, r)| {
            let at = |k: usize| cell(k).and_then(|c| map[c]);
            let mask: Vec<bool> = (0..r.len())
                .map(|k| floor.mask[k] && at(k).is_some())
                .collect();
            let less: Vec<f64> = (0..r.len()).map(|k| r[k] - at(k).unwrap_or(0.0)).collect();
            residual_stats(&less, &mask, width)
        })
        .collect();
    (rms, mean_stats(&noise))
}

fn mean_stats(all: &[Stats]) -> Stats {
    let n = all.len() as f64;
    let mut mean = Stats::default();
    for s in all {
        for k in 0..6 {
            mean.across[k] += s.across[k] / n;
            mean.down[k] += s.down[k] / n;
        }
        mean.ratio8 += s.ratio8 / n;
        mean.ratio16 += s.ratio16 / n;
    }
    mean
}

/// Inverse depth per pixel of a depth image in metres (0: no reading,
/// or outside 0.3–6 m).
fn inverse_depth(depth_m: impl Iterator<Item = f64>) -> Vec<f64> {
    depth_m
        .map(|z| {
            if (0.3..6.0).contains(&z) {
                1.0 / z
            } else {
                0.0
            }
        })
        .collect()
}

/// A real frame's floor, and the floor plane in the optical frame
/// (its up normal, its distance from the camera).
fn real_floor(path: &std::path::Path) -> (Floor, Vector3<f64>, f64) {
    let k = fr3();
    let options = PlaneOptions {
        units: Some(DepthUnits::Tum),
        fx: Some(k.fx),
        fy: Some(k.fy),
        cx: Some(k.cx),
        cy: Some(k.cy),
        ..PlaneOptions::default()
    };
    let ground = fit_file(path, &options).unwrap_or_else(|(_, e)| panic!("{e}"));
    let optical = to_optical(&ground.plane);
    // n·p + d = 0 and p = z·((u − cx)/fx, (v − cy)/fy, 1): 1/z = −n·(…)/d.
    let (n, d) = (optical.normal, optical.d);
    let start = PixelPlane {
        cu: -n.x / (d * k.fx),
        cv: -n.y / (d * k.fy),
        c0: -(n.z - n.x * k.cx / k.fx - n.y * k.cy / k.fy) / d,
    };
    let (image, _) = read_depth_image(path, Some(DepthUnits::Tum)).unwrap();
    let w = inverse_depth(image.pixels.iter().map(|&p| f64::from(p) / 5000.0));
    let up = n * d.signum();
    (refine(w, start, k.width), up, d.abs())
}

/// The simulator's floor seen from a camera whose optical frame has the
/// ground's up `up` at `height`, with the real frame's `mask`.
fn simulated_floor(
    renderer: &DepthRenderer,
    up: Vector3<f64>,
    height: f64,
    mask: &[bool],
    frame: u64,
) -> Floor {
    let k = fr3();
    // ground_from_optical: its second row (the ground's y, up) is `up` in
    // optical coordinates; the first any direction across it.
    let across = up.cross(&Vector3::z()).normalize();
    let third = across.cross(&up);
    let ground_from_optical =
        Matrix3::from_rows(&[across.transpose(), up.transpose(), third.transpose()]);
    let ground_from_sensor = Transform::from_parts(
        Translation3::new(0.0, height, 0.0),
        Rotation3::from_matrix_unchecked(ground_from_optical * sensor_from_optical().transpose()),
    );
    let raw = renderer.render(&World::flat(), &ground_from_sensor, frame);
    let model = renderer.config().depth_model;
    let w: Vec<f64> = raw
        .iter()
        .zip(mask)
        .map(|(&raw, &m)| match model.depth_m(raw) {
            Some(z) if m => 1.0 / z,
            _ => 0.0,
        })
        .collect();
    let plane = fit(&w, mask, k.width);
    let floor = Floor {
        w,
        mask: mask.to_vec(),
        plane,
    };
    // The mask's pixels the simulator read.
    let mask: Vec<bool> = floor.w.iter().map(|&w| w > 0.0).collect();
    let plane = fit(&floor.w, &mask, k.width);
    Floor {
        w: floor.w,
        mask,
        plane,
    }
}

fn cabinet_frames() -> Vec<std::path::PathBuf> {
    let dir = common::shared().join("data/real/tum-fr3-cabinet/depth_imgs");
    let mut frames: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    frames.sort();
    assert_eq!(frames.len(), 58, "the cabinet sequence has 58 frames");
    frames
}

fn line(name: &str, s: &Stats) -> String {
    let f = |x: &[f64; 6]| x.map(|v| format!("{v:.2}")).join(" ");
    format!(
        "{name:>10}: across {} | down {} | ratio 8 px {:.1}, 16 px {:.1}",
        f(&s.across),
        f(&s.down),
        s.ratio8,
        s.ratio16
    )
}

#[test]
fn the_simulated_kinects_noise_has_the_real_ones_statistics() {
    let frames = cabinet_frames();
    let real: Vec<(Floor, Vector3<f64>, f64)> = frames.iter().map(|p| real_floor(p)).collect();
    let real_stats: Vec<Stats> = real.iter().map(|(f, _, _)| stats(f, 640)).collect();
    let real_mean = mean_stats(&real_stats);

    let render = |noise: DepthNoise, with_pattern: bool| {
        let mut config = SimKinectConfig {
            intrinsics: fr3(),
            depth_model: DepthModel::inverse_linear_default(),
            noise,
            seed: 3,
            dropout_rate: 0.0,
            grazing_dropout: 0.0,
            dead_columns: 0,
            ..SimKinectConfig::default()
        };
        if !with_pattern {
            config.distortion = Default::default();
        }
        let renderer = DepthRenderer::new(&config).unwrap();
        let floors: Vec<Floor> = real
            .iter()
            .enumerate()
            .step_by(4)
            .map(|(k, (floor, up, height))| {
                simulated_floor(&renderer, *up, *height, &floor.mask, k as u64)
            })
            .collect();
        let all: Vec<Stats> = floors.iter().map(|f| stats(f, 640)).collect();
        let refs: Vec<&Floor> = floors.iter().collect();
        let (pattern, noise) = pattern_and_noise(&refs, 640);
        (mean_stats(&all), pattern, noise)
    };
    let every_fourth: Vec<&Floor> = real.iter().step_by(4).map(|(f, _, _)| f).collect();
    let (real_pattern, real_noise) = pattern_and_noise(&every_fourth, 640);
    let (simulated, simulated_pattern, simulated_noise) =
        render(SimKinectConfig::default().noise, true);
    let (former, _, _) = render(DepthNoise::white(), false);
    eprintln!("{}", line("real", &real_mean));
    eprintln!("{}", line("simulated", &simulated));
    eprintln!("{}", line("former", &former));
    eprintln!("the fixed pattern (16-px cells): real {real_pattern:.2} raw RMS, simulated {simulated_pattern:.2}");
    eprintln!("{}", line("real noise", &real_noise));
    eprintln!("{}", line("sim noise", &simulated_noise));

    let matches = |s: &Stats| {
        (0..6).all(|k| {
            (s.across[k] - real_mean.across[k]).abs() <= 0.1
                && (s.down[k] - real_mean.down[k]).abs() <= 0.1
        }) && (s.ratio8 / real_mean.ratio8).ln().abs() <= 1.5f64.ln()
            && (s.ratio16 / real_mean.ratio16).ln().abs() <= 1.5f64.ln()
    };
    // The real floor's residual is correlated far beyond a pixel.
    assert!(
        real_mean.across[5] > 0.3 && real_mean.ratio8 > 20.0,
        "{}",
        line("real", &real_mean)
    );
    assert!(
        matches(&simulated),
        "the simulator does not match the real frames:\n{}\n{}",
        line("real", &real_mean),
        line("simulated", &simulated)
    );
    // What is fixed in the image and what changes from frame to frame, each
    // as the real sensor's: the simulator's noise must not stand in for the
    // real pattern, nor its pattern for the real noise.
    assert!(
        (simulated_pattern / real_pattern).ln().abs() <= 1.25f64.ln(),
        "the fixed pattern: real {real_pattern:.2} raw RMS, simulated {simulated_pattern:.2}"
    );
    let noise_matches = (0..6).all(|k| {
        (simulated_noise.across[k] - real_noise.across[k]).abs() <= 0.15
            && (simulated_noise.down[k] - real_noise.down[k]).abs() <= 0.15
    }) && (simulated_noise.ratio8 / real_noise.ratio8).ln().abs()
        <= 1.5f64.ln()
        && (simulated_noise.ratio16 / real_noise.ratio16).ln().abs() <= 1.5f64.ln();
    assert!(
        noise_matches,
        "the noise less the fixed pattern does not match:\n{}\n{}",
        line("real", &real_noise),
        line("simulated", &simulated_noise)
    );
    assert!(
        !matches(&former),
        "independent noise should not match:\n{}",
        line("former", &former)
    );
}
