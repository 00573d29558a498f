//! The mount, its σ and a plane, as the result document writes them.

use super::*;

/// `robot_from_sensor` as cli.md prints it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MountJson {
    #[serde(deserialize_with = "finite")]
    pub alpha_deg: f64,
    #[serde(deserialize_with = "finite")]
    pub beta_deg: f64,
    #[serde(deserialize_with = "finite")]
    pub gamma_deg: f64,
    #[serde(deserialize_with = "finite")]
    pub px_mm: f64,
    #[serde(deserialize_with = "finite")]
    pub py_mm: f64,
    #[serde(deserialize_with = "finite")]
    pub pz_mm: f64,
    /// 4×4, translation in millimetres.
    #[serde(deserialize_with = "finite_4x4")]
    pub matrix: [[f64; 4]; 4],
    /// Always written; optional when read (older and other writers).
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "some_finite_4"
    )]
    pub quaternion_xyzw: Option<[f64; 4]>,
}

impl MountJson {
    /// The six parameters in the order α, β, γ, px, py, pz (degrees,
    /// millimetres).
    pub fn values(&self) -> [f64; 6] {
        self.pose().values()
    }

    /// The six parameters as a pose (the matrix and quaternion left out).
    pub fn pose(&self) -> PoseDegMm {
        PoseDegMm {
            alpha_deg: self.alpha_deg,
            beta_deg: self.beta_deg,
            gamma_deg: self.gamma_deg,
            px_mm: self.px_mm,
            py_mm: self.py_mm,
            pz_mm: self.pz_mm,
        }
    }

    pub fn from_params(p: &PoseParams) -> Self {
        let d = PoseDegMm::from_params(p);
        let m = p.to_matrix();
        let matrix = std::array::from_fn(|i| {
            std::array::from_fn(|j| {
                if j == 3 && i < 3 {
                    m[(i, j)] * 1e3
                } else {
                    m[(i, j)]
                }
            })
        });
        let q = p.quaternion();
        // A fixed sign (w ≥ 0) so that equal rotations print equally.
        let sign = if q.w < 0.0 { -1.0 } else { 1.0 };
        Self {
            alpha_deg: d.alpha_deg,
            beta_deg: d.beta_deg,
            gamma_deg: d.gamma_deg,
            px_mm: d.px_mm,
            py_mm: d.py_mm,
            pz_mm: d.pz_mm,
            matrix,
            quaternion_xyzw: Some([q.i * sign, q.j * sign, q.k * sign, q.w * sign]),
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SigmaJson {
    #[serde(deserialize_with = "number_or_nan")]
    pub alpha_deg: f64,
    #[serde(deserialize_with = "number_or_nan")]
    pub beta_deg: f64,
    #[serde(deserialize_with = "number_or_nan")]
    pub gamma_deg: f64,
    #[serde(deserialize_with = "number_or_nan")]
    pub px_mm: f64,
    #[serde(deserialize_with = "number_or_nan")]
    pub py_mm: f64,
    #[serde(deserialize_with = "number_or_nan")]
    pub pz_mm: f64,
    /// σ of the depth scale, when it was estimated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth_scale: Option<f64>,
}

impl SigmaJson {
    /// σ as the document has them (degrees, millimetres), in the order α,
    /// β, γ, px, py, pz.
    pub fn values(&self) -> [f64; 6] {
        [
            self.alpha_deg,
            self.beta_deg,
            self.gamma_deg,
            self.px_mm,
            self.py_mm,
            self.pz_mm,
        ]
    }

    /// σ in radians and metres, in the order α, β, γ, px, py, pz (the
    /// inverse of [`SigmaJson::from_radians_metres`]).
    pub fn radians_metres(&self) -> [f64; 6] {
        [
            self.alpha_deg.to_radians(),
            self.beta_deg.to_radians(),
            self.gamma_deg.to_radians(),
            self.px_mm / 1000.0,
            self.py_mm / 1000.0,
            self.pz_mm / 1000.0,
        ]
    }

    pub fn from_radians_metres(sigma: &[f64; 6]) -> Self {
        Self {
            alpha_deg: sigma[0].to_degrees(),
            beta_deg: sigma[1].to_degrees(),
            gamma_deg: sigma[2].to_degrees(),
            px_mm: sigma[3] * 1000.0,
            py_mm: sigma[4] * 1000.0,
            pz_mm: sigma[5] * 1000.0,
            depth_scale: None,
        }
    }
}

#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct PlaneJson {
    #[serde(deserialize_with = "number_or_nan")]
    pub a: f64,
    #[serde(deserialize_with = "number_or_nan")]
    pub b: f64,
    #[serde(deserialize_with = "number_or_nan")]
    pub c: f64,
    #[serde(deserialize_with = "number_or_nan")]
    pub d_m: f64,
}

impl From<&Plane> for PlaneJson {
    fn from(p: &Plane) -> Self {
        Self {
            a: p.normal.x,
            b: p.normal.y,
            c: p.normal.z,
            d_m: p.d,
        }
    }
}
