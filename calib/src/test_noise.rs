//! Noise for the unit tests, drawn without an extra crate.

use rand::Rng;

/// One standard normal draw (Box–Muller).
pub(crate) fn gaussian(rng: &mut impl Rng) -> f64 {
    let u1: f64 = rng.gen_range(f64::EPSILON..1.0);
    let u2: f64 = rng.gen();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Raw readings as metric values for the vector loops' tests: a thousandth
/// of each, the dropouts (2047) infinite and one in seven NaN.
pub(crate) fn metric_with_nan(raw: &[u16]) -> Vec<f32> {
    raw.iter()
        .enumerate()
        .map(|(k, &r)| match (r, k % 7) {
            (2047, _) => f32::INFINITY,
            (_, 3) => f32::NAN,
            (r, _) => f32::from(r) * 1e-3,
        })
        .collect()
}
