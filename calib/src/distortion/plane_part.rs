//! The pattern's plane part (a constant and two gradients of the raw values)
//! from the geometry across poses: the mount solved again for each value
//! (variable projection), the part's covariance by a sandwich over poses.

use super::*;

/// The plane part of the pattern in raw units: a constant and its gradients
/// per 100 pixels along the columns and the rows.
pub(super) type PlanePart = Vector3<f64>;

/// The plane part in inverse depth (1/m) on `c0, cu, cv`.
pub(super) fn plane_part_inverse_depth(
    part: &PlanePart,
    raw_per_inverse_depth: f64,
) -> Vector3<f64> {
    Vector3::new(part.x, part.y / 100.0, part.z / 100.0) / raw_per_inverse_depth
}

/// The plane part's estimate.
#[derive(Debug, Clone)]
pub(super) struct PlanePartEstimate {
    pub(super) value: PlanePart,
    /// Its covariance, raw units.
    pub(super) covariance: Matrix3<f64>,
    /// Its χ² against none.
    pub(super) chi2: f64,
    /// How the six parameters move with it (radians and metres per unit).
    pub(super) sensitivity: nalgebra::Matrix6x3<f64>,
    pub(super) taken: bool,
}

/// The plane part by variable projection: Gauss-Newton on the poses'
/// whitened residuals, the mount (and scale) solved again at each value.
pub(super) struct PlanePartSolve<'a> {
    pub(super) observations: &'a [Observation],
    /// The observations with ground residuals (the pattern's poses).
    pub(super) indices: &'a [usize],
    pub(super) settings: &'a SolveSettings,
    pub(super) intrinsics: Intrinsics,
    pub(super) raw_per_inverse_depth: f64,
    /// σ of one pose's normal (radians) and offset (metres) to whiten by.
    pub(super) noise: (f64, f64),
    /// The depth scale of the solve at no plane part, where it was not
    /// estimated (the poses pin it too loosely, or it was given): the
    /// derivatives' solves keep it, as they keep the poses that solve set
    /// aside. Decided afresh, each solve estimated the scale, found it too
    /// loose and solved again at the fallback: two to seven solves for
    /// one, most of the plane part's time.
    pub(super) scale_not_estimated: Option<f64>,
}

/// Parameters fitted to the plane part's residuals: the mount's six, the
/// depth scale and the plane part's three (the residuals' degrees of
/// freedom are their count less these).
pub(super) const PARAMETERS_FITTED: f64 = 10.0;

/// Steps of the numerical derivatives, raw units (and per 100 pixels).
pub(super) const PLANE_PART_STEP: f64 = 0.02;

/// The plane part's problem linearised at one value.
pub(super) struct Linearised {
    /// The poses' whitened residuals.
    pub(super) residuals: DVector<f64>,
    /// Their derivatives by the plane part's three parameters.
    pub(super) jacobian: DMatrix<f64>,
    /// `JᵀJ`: the plane part's information, in units of the whitening noise.
    pub(super) information: Matrix3<f64>,
    /// How the six parameters move with it (radians and metres per unit).
    pub(super) sensitivity: nalgebra::Matrix6x3<f64>,
}

/// What estimating a pattern's plane part would add to the mount's
/// covariance (radians and metres), on `observations` that carry noise of
/// `noise` (σ of one pose's normal in radians, of its offset in metres):
/// `S·C·Sᵀ`, with `C` the plane part's covariance and `S` how the mount
/// moves with it. For planning: on exact planes predicted for a schedule it
/// says what a found pattern will cost before the robot moves. The result
/// does not depend on the intrinsics or the depth model, which only
/// re-parametrise the plane part; the defaults are used.
pub fn plane_part_cost(
    observations: &[Observation],
    settings: &SolveSettings,
    noise: (f64, f64),
) -> Option<Matrix6<f64>> {
    let intrinsics = Intrinsics::default();
    let (_, b) = crate::depth::DepthModel::inverse_linear_default().inverse_depth_affine();
    let indices: Vec<usize> = (0..observations.len()).collect();
    let problem = PlanePartSolve {
        observations,
        indices: &indices,
        settings,
        intrinsics,
        raw_per_inverse_depth: 1.0 / b,
        noise,
        // As the settings say: the exact planes of a plan pin the scale
        // as the schedule does.
        scale_not_estimated: None,
    };
    let linearised = problem.linearise(&PlanePart::zeros())?;
    let covariance = linearised.information.try_inverse()?;
    let s = linearised.sensitivity;
    Some(s * covariance * s.transpose())
}

/// The mount's covariance from `exact` observations (planes as the mount
/// predicts them) under `settings`, and the same with the plane part's cost
/// added (`None` when the plane part is not observable): what `plan`
/// predicts for a schedule with a pattern, and what the pattern's gate
/// judges a calibration's poses by ([`angle_sigma_growth_by_geometry`]).
pub fn covariance_with_plane_part(
    exact: &[Observation],
    settings: &SolveSettings,
    noise: (f64, f64),
) -> Result<(Matrix6<f64>, Option<Matrix6<f64>>), SolveError> {
    let known = solve::solve(exact, settings)?.covariance;
    Ok((
        known,
        plane_part_cost(exact, settings, noise).map(|cost| known + cost),
    ))
}

/// Each angle's σ growth (α, β, γ) from estimating the plane part, by the
/// poses' geometry alone: the poses `solution` used, each seeing the plane
/// its mount predicts exactly, with `noise` on each (σ of a normal in
/// radians, of an offset in metres), as `plan` predicts a schedule's. The
/// measured σ grow by this and by the noise met besides: under correlated
/// noise designed-52's measured growth spread from 5.7 to 15 over seeds of
/// the same recording's kind (white noise: 5.2–6.4), while this is the
/// schedule's alone, which the gate `pattern_angle_sigma_growth_max` is
/// there to judge. `None` when the plane part is not observable.
pub(super) fn angle_sigma_growth_by_geometry(
    observations: &[Observation],
    solution: &Solution,
    settings: &SolveSettings,
    noise: (f64, f64),
) -> Option<[f64; 3]> {
    let noise = (noise.0.max(1e-9), noise.1.max(1e-9));
    let exact: Vec<Observation> = observations
        .iter()
        .filter(|o| solution.poses.iter().any(|p| p.index == o.index && p.used))
        .map(|o| {
            solve::exact_observation(o.index, o.ground_from_robot, &solution.robot_from_sensor)
        })
        .collect();
    let settings = SolveSettings {
        normal_sigma_floor: noise.0,
        offset_sigma_floor: noise.1,
        noise_from_residuals: false,
        ..*settings
    };
    let (known, with) = covariance_with_plane_part(&exact, &settings, noise).ok()?;
    let with = with?;
    let growth = [0, 1, 2].map(|k| (with[(k, k)].max(0.0) / known[(k, k)]).sqrt());
    growth.iter().all(|g| g.is_finite()).then_some(growth)
}

impl PlanePartSolve<'_> {
    /// The observations with `part` taken out of the pattern's poses.
    fn corrected(&self, part: &PlanePart) -> Vec<Observation> {
        let delta = -plane_part_inverse_depth(part, self.raw_per_inverse_depth);
        let mut corrected = self.observations.to_vec();
        for &k in self.indices {
            corrected[k] = moved(&self.observations[k], &delta, &self.intrinsics);
        }
        corrected
    }

    /// The whitened residuals of the pattern's poses at `part`, with the
    /// solve's estimate there ([`solve::solve_estimate`]: the derivatives
    /// read the mount and the scale, not their σ). The poses the first
    /// solve set aside stay aside, and no more are looked for: the
    /// derivatives must not jump with that choice, and the search is most
    /// of a solve's time.
    fn residuals(&self, part: &PlanePart) -> Option<(DVector<f64>, Solution)> {
        let mut corrected = self.corrected(part);
        for (k, observation) in corrected.iter_mut().enumerate() {
            if !self.indices.contains(&k) && observation.set_aside.is_none() {
                observation.set_aside = Some("set aside by the first solve".into());
            }
        }
        let settings = SolveSettings {
            max_outlier_fraction: 0.0,
            depth_scale: self
                .scale_not_estimated
                .map_or(self.settings.depth_scale, solve::DepthScaleSetting::Fixed),
            ..*self.settings
        };
        let solution = solve::solve_estimate(&corrected, &settings).ok()?;
        let (sigma_normal, sigma_offset) = (self.noise.0.max(1e-9), self.noise.1.max(1e-9));
        let mut values = Vec::with_capacity(3 * self.indices.len());
        let scale = solution.depth_scale.value;
        for &k in self.indices {
            let observed = &corrected[k];
            let predicted =
                solve::predict(&solution.robot_from_sensor, &observed.ground_from_robot);
            // A fixed tangent basis: that of the uncorrected normal.
            let (e1, e2) = solve::tangent_basis(&self.observations[k].plane.normal);
            let dn = predicted.normal - observed.plane.normal;
            values.push(e1.dot(&dn) / sigma_normal);
            values.push(e2.dot(&dn) / sigma_normal);
            values.push((predicted.d - observed.plane.d / scale) / sigma_offset);
        }
        Some((DVector::from_vec(values), solution))
    }

    /// The whitened residuals at `part`, their derivatives by the plane
    /// part, and how the mount moves with it.
    fn linearise(&self, part: &PlanePart) -> Option<Linearised> {
        // The residuals at `part` and a step along each of its three
        // parameters: four solves, independent, so side by side.
        let mut solved: Vec<Option<(DVector<f64>, Solution)>> = (0..4)
            .into_par_iter()
            .map(|j| {
                let mut at = *part;
                if j > 0 {
                    at[j - 1] += PLANE_PART_STEP;
                }
                self.residuals(&at)
            })
            .collect();
        let (r0, at_part) = solved[0].take()?;
        let mut jacobian = DMatrix::zeros(r0.len(), 3);
        let mut sensitivity = nalgebra::Matrix6x3::zeros();
        let mount = at_part.robot_from_sensor.to_vector();
        for j in 0..3 {
            let (r, moved) = solved[j + 1].take()?;
            if r.len() != r0.len() {
                return None;
            }
            jacobian.set_column(j, &((r - &r0) / PLANE_PART_STEP));
            let mut change = moved.robot_from_sensor.to_vector() - mount;
            for angle in 0..3 {
                change[angle] = wrap(change[angle]);
            }
            sensitivity.set_column(j, &(change / PLANE_PART_STEP));
        }
        let information = jacobian.transpose() * &jacobian;
        let information = Matrix3::from_fn(|i, j| information[(i, j)]);
        Some(Linearised {
            residuals: r0,
            jacobian,
            information,
            sensitivity,
        })
    }

    pub(super) fn estimate(&self) -> Option<PlanePartEstimate> {
        let mut part = PlanePart::zeros();
        let mut last = None;
        for _ in 0..6 {
            let Linearised {
                residuals: r0,
                jacobian,
                information,
                sensitivity,
            } = self.linearise(&part)?;
            let covariance = information.try_inverse()?;
            let gradient = jacobian.transpose() * &r0;
            let step = -(covariance * Vector3::new(gradient[0], gradient[1], gradient[2]));
            // The noise the residuals show, with the pattern's part taken out.
            let dof = (r0.len() as f64 - PARAMETERS_FITTED).max(1.0);
            let factor = ((r0.norm_squared() - gradient.dot(&-step)) / dof).max(1e-6);
            // Its covariance from the poses' own residuals, never below
            // what their average noise gives: the poses are not equally
            // noisy (far ground fits worse, feet differ), and with every
            // pose taken as the average the plane part's σ came out 20–45 %
            // too small (its errors 1.22–1.45σ RMS, the pitch's 1.3–1.7σ).
            let covariance = at_least(
                &per_pose_sandwich(&covariance, &jacobian, &r0),
                &(covariance * factor),
            );
            last = Some((covariance, sensitivity));
            part += step;
            if step.amax() < 1e-3 {
                break;
            }
        }
        let (covariance, sensitivity) = last?;
        let chi2 = covariance
            .try_inverse()
            .map_or(0.0, |h| (part.transpose() * h * part)[(0, 0)]);
        Some(PlanePartEstimate {
            value: part,
            covariance,
            chi2,
            sensitivity,
            taken: true,
        })
    }

    /// The solve at the plane part `part`, with the outliers looked for:
    /// made for a part that is taken only (one reported but not taken has
    /// the solve without it, and this one was 3–5 ms of nothing).
    pub(super) fn solve_at(&self, part: &PlanePart) -> Option<Solution> {
        solve::solve(&self.corrected(part), self.settings).ok()
    }
}

/// The plane part's covariance from the residuals pose by pose (a sandwich
/// clustered by pose, `(JᵀJ)⁻¹·Σ_i J_iᵀ r_i r_iᵀ J_i·(JᵀJ)⁻¹`, times
/// `n/(n − 10)` for the [`PARAMETERS_FITTED`]): right whatever the poses'
/// noise, where `σ²·(JᵀJ)⁻¹` assumes every pose as noisy as the average.
/// `inverse_information` is `(JᵀJ)⁻¹`.
pub(super) fn per_pose_sandwich(
    inverse_information: &Matrix3<f64>,
    jacobian: &DMatrix<f64>,
    residuals: &DVector<f64>,
) -> Matrix3<f64> {
    let mut meat = Matrix3::zeros();
    for pose in 0..residuals.len() / 3 {
        let mut score = Vector3::zeros();
        for row in 3 * pose..3 * pose + 3 {
            for j in 0..3 {
                score[j] += jacobian[(row, j)] * residuals[row];
            }
        }
        meat += score * score.transpose();
    }
    let n = residuals.len() as f64;
    inverse_information * meat * inverse_information * (n / (n - PARAMETERS_FITTED).max(1.0))
}

/// The smallest covariance (in every direction) at least both `a` and `b`:
/// `b^½·V·max(Λ, 1)·Vᵀ·b^½`, with `VΛVᵀ` the eigen-decomposition of
/// `b^-½·a·b^-½`. `b` when it cannot be formed.
pub(super) fn at_least(a: &Matrix3<f64>, b: &Matrix3<f64>) -> Matrix3<f64> {
    let Some(root) = b.cholesky().map(|c| c.l()) else {
        return *b;
    };
    let Some(inverse_root) = root.try_inverse() else {
        return *b;
    };
    let relative = inverse_root * a * inverse_root.transpose();
    let relative = (relative + relative.transpose()) / 2.0;
    let eigen = relative.symmetric_eigen();
    let clamped = eigen.eigenvectors
        * Matrix3::from_diagonal(&eigen.eigenvalues.map(|l| l.max(1.0)))
        * eigen.eigenvectors.transpose();
    root * clamped * root.transpose()
}

/// An angle's difference brought into (−π, π].
pub(super) fn wrap(angle: f64) -> f64 {
    let turned = angle.rem_euclid(std::f64::consts::TAU);
    if turned > std::f64::consts::PI {
        turned - std::f64::consts::TAU
    } else {
        turned
    }
}
