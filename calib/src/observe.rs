//! From one pose's evidence to an observation for the solve: the real body
//! pose from the feet (paper 4.2) and the ground from the depth frames (paper
//! 4.1), the ground chosen with a prior from the nominal mount. Shared by the
//! offline replay and the live calibration session, so that both compute the
//! same thing from the same evidence.

use nalgebra::Vector3;

use crate::body::{Feet, GroundFrame, MIN_FEET, MIN_FEET_TO_FIND_A_SLIP};
use crate::geometry::{PoseDegMm, Transform};
use crate::plane::{
    fit_ground, FitBuffers, GroundFit, GroundFitMethod, GroundPrior, PlaneFitSettings,
};
use crate::residuals::{GroundResiduals, ScatterMeasured};
use crate::sensor::{DepthCamera, DepthEncoding, DepthModel, DepthRange, Intrinsics};
use crate::solve::Observation;
use serde::{Deserialize, Serialize};

/// The rough `robot_from_sensor` known before calibrating, with how far off
/// it may be: it tells which plane in view is the ground, never the answer.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NominalMount {
    pub alpha_deg: f64,
    pub beta_deg: f64,
    pub gamma_deg: f64,
    pub px_mm: f64,
    pub py_mm: f64,
    pub pz_mm: f64,
    pub tolerance_deg: f64,
    pub tolerance_mm: f64,
}

impl NominalMount {
    /// The nominal mount from six values (degrees, millimetres, as
    /// `--nominal-mount a,b,g,x,y,z`), with the tolerances of recording.md's
    /// example.
    pub fn from_values(values: [f64; 6]) -> Self {
        Self {
            alpha_deg: values[0],
            beta_deg: values[1],
            gamma_deg: values[2],
            px_mm: values[3],
            py_mm: values[4],
            pz_mm: values[5],
            tolerance_deg: 15.0,
            tolerance_mm: 200.0,
        }
    }

    /// The mount's pose.
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

    /// Whether every number is usable.
    pub fn validate(&self) -> Result<(), String> {
        if !self.pose().is_finite()
            || !self.tolerance_deg.is_finite()
            || !self.tolerance_mm.is_finite()
        {
            return Err("nominal_mount has a value that is not a finite number".into());
        }
        if !(self.tolerance_deg > 0.0 && self.tolerance_deg <= 90.0) {
            return Err(format!(
                "nominal_mount.tolerance_deg must lie in (0, 90], not {}",
                self.tolerance_deg
            ));
        }
        if self.tolerance_mm <= 0.0 {
            return Err(format!(
                "nominal_mount.tolerance_mm must be positive, not {}",
                self.tolerance_mm
            ));
        }
        Ok(())
    }
}

/// Where the body pose of an observation comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BodyPoseSource {
    /// From the feet the lower computer reports (the method).
    Feet,
    /// The commanded pose, trusted as if reached. Only for showing what that
    /// costs: the real pose differs by the robot's own errors (paper 4.2).
    Commanded,
}

/// Tuning of the per-pose processing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObserveSettings {
    pub plane: PlaneFitSettings,
    /// A foot farther than this from where the other feet put it has
    /// slipped, metres: the most; once the feet have shown their own
    /// agreement the limit follows it below this ([`SLIP_SCATTERS`]).
    pub slip_threshold_m: f64,
    pub body_pose_source: BodyPoseSource,
    pub depth_range: DepthRange,
    /// Whether each pose's ground residuals are summed for the depth
    /// pattern: a calibration estimates one, a check against a calibration
    /// takes the calibration's and needs none.
    pub ground_residuals: bool,
    /// What the residuals measure of the readings' scatter: the cells'
    /// scatter against depth too for a camera of unknown kind (a bag's).
    pub scatter: ScatterMeasured,
}

impl Default for ObserveSettings {
    fn default() -> Self {
        Self {
            plane: PlaneFitSettings::default(),
            slip_threshold_m: 0.010,
            body_pose_source: BodyPoseSource::Feet,
            depth_range: DepthRange::default(),
            ground_residuals: true,
            scatter: ScatterMeasured::Pooled,
        }
    }
}

/// A small count as the notes write it ("five"), a larger one in digits.
fn count_in_words(n: usize) -> String {
    const WORDS: [&str; 8] = ["no", "one", "two", "three", "four", "five", "six", "seven"];
    WORDS
        .get(n)
        .map_or_else(|| n.to_string(), |w| (*w).to_string())
}

/// Feet in millimetres (files, messages) to metres.
pub fn feet_from_mm(feet_mm: &[[f64; 3]]) -> Result<Feet, String> {
    if feet_mm.len() < MIN_FEET {
        return Err(format!(
            "{} feet cannot fix a body: at least {MIN_FEET} are needed",
            feet_mm.len()
        ));
    }
    // A hundred metres is far beyond any leg: larger numbers are a fault,
    // and are named as one rather than surfacing as a NaN further on.
    const MAX_FOOT_MM: f64 = 100_000.0;
    for (i, foot) in feet_mm.iter().enumerate() {
        if let Some(v) = foot
            .iter()
            .find(|v| !v.is_finite() || v.abs() > MAX_FOOT_MM)
        {
            return Err(format!(
                "foot {} is at {v} mm from the body: not a foot of this robot (at most ±{MAX_FOOT_MM} mm)",
                i + 1
            ));
        }
    }
    Ok(feet_mm
        .iter()
        .map(|[x, y, z]| Vector3::new(*x, *y, *z) / 1000.0)
        .collect())
}

/// Where the ground should be in the sensor frame, at a body pose, from the
/// nominal mount: its up direction and height, within the mount's
/// tolerances. Without a mount, any plane facing the sensor from below its
/// optical axis: up in the image, within 89°.
pub fn ground_prior(nominal: Option<&NominalMount>, ground_from_robot: &Transform) -> GroundPrior {
    match nominal {
        Some(m) => {
            let mount = m.pose().to_params();
            let r = ground_from_robot.rotation.matrix();
            let up_robot = Vector3::new(r[(1, 0)], r[(1, 1)], r[(1, 2)]);
            let up_sensor = mount.rotation_matrix().transpose() * up_robot;
            let height = up_robot.dot(&mount.translation) + ground_from_robot.translation.vector.y;
            GroundPrior {
                up: up_sensor,
                up_tolerance: m.tolerance_deg.to_radians(),
                height: Some((height, m.tolerance_mm / 1000.0)),
            }
        }
        None => GroundPrior::up_only(Vector3::y(), 89f64.to_radians()),
    }
}

/// Turns one pose's evidence, its feet and its frames, into one [`Observation`].
#[derive(Debug, Clone)]
pub struct PoseObserver {
    camera: DepthCamera,
    ground_frame: GroundFrame,
    nominal: Option<NominalMount>,
    settings: ObserveSettings,
}

/// The body pose of one observation, and whether it can be trusted.
#[derive(Debug, Clone, PartialEq)]
pub struct BodyEstimate {
    pub ground_from_robot: Transform,
    /// Why the pose must be set aside (two feet that moved), if it must.
    pub set_aside: Option<String>,
    /// A slipped foot left out of the body pose, in words.
    pub note: Option<String>,
}

/// Follows the feet from pose to pose: the ground frame of the home stance,
/// with a foot that slipped planted anew where it stays. Poses go through it
/// in the order they were visited.
#[derive(Debug, Clone)]
pub struct FeetTracker {
    ground_frame: GroundFrame,
    slip_threshold_m: f64,
    source: BodyPoseSource,
    /// At each pose where no foot slipped, the farthest any foot lay from
    /// where the others put it: the feet's own scatter.
    worst_misses: Vec<f64>,
}

/// Poses without a slip after which the slip limit follows the feet's own
/// scatter rather than the configured one alone.
pub const SLIP_SCATTER_POSES: usize = 8;

/// The slip limit, once the feet's scatter is known: this many times the
/// median of the poses' farthest misses (for feet whose noise is normal, the
/// farthest of six misses exceeded three times its median in none of 2·10⁶
/// simulated poses: four leaves room for a heavier tail), never below [`MIN_SLIP_M`] nor above the configured limit. A
/// foot that sank 6 mm into soft ground at pose 30 (the simulator's feet,
/// 0.1 mm of noise) stayed under the configured 10 mm, and a calibration
/// was accepted with β 0.060° off (5.4σ; docs/method.md).
pub const SLIP_SCATTERS: f64 = 4.0;

/// The fewest feet for which the limit follows their scatter. Four feet
/// in a parallelogram explain a foot that sank straight down equally well
/// leaving out any of them (each miss is the sink), so a small sink would
/// name a foot at random and plant the wrong one anew (a review's model of
/// a 500 × 300 mm quadruped: the wrong foot every time, the body then
/// 0.45-0.91° off); from five on, the foot that sank is the one whose miss
/// the others agree on.
pub const MIN_FEET_TO_FOLLOW_THE_FEET: usize = MIN_FEET_TO_FIND_A_SLIP + 1;

/// The least slip limit, metres: below it a foot's miss is taken for the
/// robot's own play, whatever the feet's scatter says.
pub const MIN_SLIP_M: f64 = 0.002;

/// The limit a foot's miss is held to, metres, and where it came from.
#[derive(Debug, Clone, Copy, PartialEq)]
enum SlipLimit {
    Configured(f64),
    /// From the feet's scatter: the limit and the median of the poses'
    /// farthest misses.
    FromTheFeet {
        limit: f64,
        median_miss: f64,
    },
}

impl SlipLimit {
    fn metres(self) -> f64 {
        match self {
            SlipLimit::Configured(limit) | SlipLimit::FromTheFeet { limit, .. } => limit,
        }
    }

    /// "limit 2.0 mm …", as the notes say it.
    fn describe(self) -> String {
        match self {
            SlipLimit::Configured(limit) => format!("limit {:.1} mm", limit * 1e3),
            SlipLimit::FromTheFeet { limit, median_miss } if limit <= MIN_SLIP_M => format!(
                "limit {:.1} mm, the least, as the feet agreed to within {:.1} mm at a typical pose before",
                limit * 1e3,
                median_miss * 1e3
            ),
            SlipLimit::FromTheFeet { limit, median_miss } => format!(
                "limit {:.1} mm, {SLIP_SCATTERS:.0} times the {:.1} mm within which the feet agreed at a typical pose before",
                limit * 1e3,
                median_miss * 1e3
            ),
        }
    }
}

impl FeetTracker {
    /// The real body pose from the feet reported at a pose (or the commanded
    /// pose, if so configured).
    ///
    /// One foot that moved since it was planted is left out (the other
    /// planted feet, three or more, fix the body) and planted anew where it
    /// is; two feet that moved set the pose aside.
    pub fn body_pose(
        &mut self,
        commanded: &PoseDegMm,
        feet_mm: &[[f64; 3]],
    ) -> Result<BodyEstimate, String> {
        let feet = feet_from_mm(feet_mm)?;
        let limit = self.slip_limit();
        let from_feet = self
            .ground_frame
            .body_pose(&feet, limit.metres())
            .map_err(|e| e.to_string())?;
        if from_feet.slipped_foot.is_none() {
            self.worst_misses.extend(from_feet.worst_miss);
        }
        let limit_words = limit.describe();
        let (set_aside, note) = match (from_feet.slipped_foot, from_feet.second_slipped_foot) {
            (Some((a, miss_a)), Some((b, miss_b))) => (
                Some(format!(
                    "feet {a} and {b} slipped: they are {:.1} and {:.1} mm from where they were planted ({limit_words}), so the feet do not fix the body pose",
                    miss_a * 1e3,
                    miss_b * 1e3
                )),
                None,
            ),
            (Some((foot, miss)), None) => {
                self.ground_frame
                    .replant(foot, &feet, &from_feet.ground_from_robot);
                (
                    None,
                    Some(format!(
                        "foot {foot} slipped ({:.1} mm from where it was planted, {limit_words}): the body pose is the other {} feet's, and the foot counts from where it is now",
                        miss * 1e3,
                        count_in_words(feet.len() - 1)
                    )),
                )
            }
            _ => (None, None),
        };
        let ground_from_robot = match self.source {
            BodyPoseSource::Feet => from_feet.ground_from_robot,
            BodyPoseSource::Commanded => commanded.to_params().to_transform(),
        };
        Ok(BodyEstimate {
            ground_from_robot,
            set_aside,
            note,
        })
    }

    /// The configured limit until [`SLIP_SCATTER_POSES`] poses without a
    /// slip show the feet's scatter; then [`SLIP_SCATTERS`] times its median,
    /// within [`MIN_SLIP_M`] and the configured limit.
    fn slip_limit(&self) -> SlipLimit {
        if self.worst_misses.len() < SLIP_SCATTER_POSES
            || self.ground_frame.feet_ground.len() < MIN_FEET_TO_FOLLOW_THE_FEET
        {
            return SlipLimit::Configured(self.slip_threshold_m);
        }
        let median = crate::solve::median(&self.worst_misses);
        let from_the_feet = (SLIP_SCATTERS * median).max(MIN_SLIP_M);
        if from_the_feet < self.slip_threshold_m {
            SlipLimit::FromTheFeet {
                limit: from_the_feet,
                median_miss: median,
            }
        } else {
            SlipLimit::Configured(self.slip_threshold_m)
        }
    }
}

impl PoseObserver {
    /// A processor for one calibration: the sensor model, the ground frame from
    /// the home stance's feet, and the nominal mount (if known) for the prior.
    pub fn new(
        model: DepthModel,
        intrinsics: Intrinsics,
        home_feet_mm: &[[f64; 3]],
        nominal: Option<NominalMount>,
        settings: ObserveSettings,
    ) -> Result<Self, String> {
        Self::for_encoding(
            DepthEncoding::Raw11(model),
            intrinsics,
            home_feet_mm,
            nominal,
            settings,
        )
    }

    /// [`PoseObserver::new`] for frames of any encoding (metric depth from
    /// another robot's bag).
    pub fn for_encoding(
        encoding: DepthEncoding,
        intrinsics: Intrinsics,
        home_feet_mm: &[[f64; 3]],
        nominal: Option<NominalMount>,
        settings: ObserveSettings,
    ) -> Result<Self, String> {
        let home = feet_from_mm(home_feet_mm)?;
        let ground_frame =
            GroundFrame::from_home_feet(&home).map_err(|e| format!("home stance: {e}"))?;
        let camera = DepthCamera::new(encoding, intrinsics, settings.depth_range);
        Ok(Self {
            camera,
            ground_frame,
            nominal,
            settings,
        })
    }

    /// This observer with the Kinect's depth pattern a calibration found
    /// taken out of every frame (a check against that calibration).
    pub fn with_depth_correction(mut self, correction: &crate::depth::DepthCorrection) -> Self {
        self.camera = self.camera.with_depth_correction(correction);
        self
    }

    /// The converter from raw frames to points.
    pub fn camera(&self) -> &DepthCamera {
        &self.camera
    }

    /// A note for the operator when there is no nominal mount to tell which
    /// plane is the ground.
    pub fn prior_note(&self) -> Option<String> {
        self.nominal.is_none().then(|| {
            "no nominal mount was given: the ground is taken as the dominant plane facing the sensor (give --nominal-mount to rule out walls and boxes)".to_string()
        })
    }

    /// What the number of feet cannot do, in words: three fix the body with
    /// none to spare, so a foot that slipped cannot be found.
    pub fn feet_note(&self) -> Option<String> {
        let feet = self.ground_frame.feet_ground.len();
        (feet < MIN_FEET_TO_FIND_A_SLIP).then(|| {
            format!(
                "the body pose comes from {feet} planted feet, which fix it with none to spare: a foot that slipped cannot be found (it takes {MIN_FEET_TO_FIND_A_SLIP}), so the result rests on every foot having held"
            )
        })
    }

    /// A tracker of the feet from the home stance on, for one pass over the
    /// poses in the order they were visited.
    pub fn feet_tracker(&self) -> FeetTracker {
        FeetTracker {
            ground_frame: self.ground_frame.clone(),
            slip_threshold_m: self.settings.slip_threshold_m,
            source: self.settings.body_pose_source,
            worst_misses: Vec::new(),
        }
    }

    /// Where the ground should be, in the sensor frame, at a body pose.
    pub fn prior(&self, ground_from_robot: &Transform) -> GroundPrior {
        ground_prior(self.nominal.as_ref(), ground_from_robot)
    }

    /// The observation of one pose from its body pose and its frames (raw
    /// values), reusing `buffers` from pose to pose.
    pub fn observe(
        &self,
        index: u32,
        body: &BodyEstimate,
        frames: &[&[u16]],
        buffers: &mut FitBuffers,
    ) -> Result<Observation, String> {
        self.observe_with_fit(index, body, frames, buffers)
            .map(|(observation, _)| observation)
    }

    /// [`PoseObserver::observe`], with the ground fit behind the observation
    /// (to show which pixels were taken for the ground).
    pub fn observe_with_fit(
        &self,
        index: u32,
        body: &BodyEstimate,
        frames: &[&[u16]],
        buffers: &mut FitBuffers,
    ) -> Result<(Observation, GroundFit), String> {
        let prior = self.prior(&body.ground_from_robot);
        let fit = fit_ground(frames, &self.camera, &prior, &self.settings.plane, buffers)
            .map_err(|e| e.to_string())?;
        let observation = Observation {
            index,
            ground_from_robot: body.ground_from_robot,
            plane: fit.plane,
            plane_covariance: Some(fit.covariance),
            inliers: Some(fit.inliers),
            set_aside: body.set_aside.clone(),
            note: body.note.clone(),
            ground_residuals: self
                .settings
                .ground_residuals
                .then(|| self.residuals(frames, &prior, &fit, buffers))
                .flatten()
                .map(std::sync::Arc::new),
        };
        Ok((observation, fit))
    }

    /// The ground's residuals for the depth pattern: the fit's own, or, for
    /// the paper's fit (which corrects no pattern), the default fit's made
    /// beside it, so that a warped depth image is still seen and judged.
    fn residuals(
        &self,
        frames: &[&[u16]],
        prior: &GroundPrior,
        fit: &GroundFit,
        buffers: &mut FitBuffers,
    ) -> Option<GroundResiduals> {
        match fit.method {
            GroundFitMethod::Disparity => GroundResiduals::of_fitted_measuring(
                frames,
                &self.camera,
                fit,
                buffers,
                self.settings.scatter,
            ),
            GroundFitMethod::Paper => {
                let settings = PlaneFitSettings {
                    method: GroundFitMethod::Disparity,
                    ..self.settings.plane
                };
                let beside = fit_ground(frames, &self.camera, prior, &settings, buffers).ok()?;
                let scatter = self.settings.scatter;
                GroundResiduals::of_fitted_measuring(
                    frames,
                    &self.camera,
                    &beside,
                    buffers,
                    scatter,
                )
                .map(|r| r.beside_another_fit(beside.plane, beside.covariance))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::PoseParams;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// `feet` feet (six: a hexagon; four: a square; 800 mm from the body's
    /// axis, 600 mm below it) tracked over `poses` body poses (tilts to 15°,
    /// heights 550-750 mm), each foot reported with `noise_mm` of noise per
    /// axis, foot 3 sunk `sink_mm` from pose 20 on: the poses at which a
    /// slip was named.
    fn slips_named(feet: u32, noise_mm: f64, sink_mm: f64, poses: usize) -> Vec<(usize, String)> {
        let home_mm: Vec<[f64; 3]> = (0..feet)
            .map(|k| {
                let step = 360.0 / f64::from(feet);
                let angle = (step / 2.0 + step * f64::from(k)).to_radians();
                [800.0 * angle.cos(), -600.0, 800.0 * angle.sin()]
            })
            .collect();
        let frame = GroundFrame::from_home_feet(&feet_from_mm(&home_mm).unwrap()).unwrap();
        let planted = frame.feet_ground.clone();
        let mut tracker = FeetTracker {
            ground_frame: frame,
            slip_threshold_m: 0.010,
            source: BodyPoseSource::Feet,
            worst_misses: Vec::new(),
        };
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut named = Vec::new();
        for k in 0..poses {
            let tilt = |rng: &mut ChaCha8Rng| rng.gen_range(-15f64..15.0).to_radians();
            let truth = PoseParams::new(
                tilt(&mut rng),
                tilt(&mut rng),
                tilt(&mut rng),
                Vector3::new(0.0, rng.gen_range(0.55..0.75), 0.0),
            )
            .to_transform();
            let feet_mm: Vec<[f64; 3]> = planted
                .iter()
                .enumerate()
                .map(|(foot, g)| {
                    let mut g = *g;
                    if foot == 2 && k >= 20 {
                        g.y -= sink_mm * 1e-3;
                    }
                    let f = (truth.inverse() * nalgebra::Point3::from(g)).coords * 1e3;
                    std::array::from_fn(|a| f[a] + noise_mm * crate::test_noise::gaussian(&mut rng))
                })
                .collect();
            // The commanded pose is not read: the feet give the pose.
            let commanded = PoseDegMm::from_values([0.0, 0.0, 0.0, 0.0, 600.0, 0.0]);
            let estimate = tracker.body_pose(&commanded, &feet_mm).unwrap();
            if let Some(note) = estimate.note.or(estimate.set_aside) {
                named.push((k, note));
            }
        }
        named
    }

    /// A foot that sinks 4 mm into soft ground, below the configured 10 mm,
    /// is named once the feet have shown how well they agree (0.1 mm of
    /// noise, as the simulator's): the configured limit alone let a 6-mm
    /// sink move β 0.060° (docs/method.md). Feet ten times noisier (their
    /// limit then the configured one, four times their median miss being
    /// more) name nothing that did not move; nor do four feet, which cannot
    /// tell which of them sank a little (the configured limit stays).
    #[test]
    fn a_sinking_foot_is_named_at_the_feet_own_scatter() {
        let named = slips_named(6, 0.1, 4.0, 40);
        assert_eq!(named.len(), 1, "{named:?}");
        let (pose, note) = &named[0];
        assert_eq!(*pose, 20);
        assert!(
            note.starts_with("foot 3 slipped (")
                && note.contains("limit 2.0 mm, the least, as the feet agreed"),
            "{note}"
        );
        assert_eq!(slips_named(6, 0.1, 0.0, 200), Vec::new());
        assert_eq!(slips_named(6, 1.0, 0.0, 200), Vec::new());
        // The noisier feet's limit is above the sink: it stays unnamed,
        // as with the configured limit.
        assert_eq!(slips_named(6, 1.0, 4.0, 40), Vec::new());
        assert_eq!(slips_named(4, 0.1, 4.0, 40), Vec::new());
        assert_eq!(slips_named(4, 0.1, 12.0, 40).len(), 1);
    }

    #[test]
    fn feet_out_of_reach_are_named() {
        let mut feet = [[600.0, -600.0, 400.0]; 6];
        assert!(feet_from_mm(&feet).is_ok());
        assert!(feet_from_mm(&feet[..4]).is_ok(), "a quadruped's");
        let e = feet_from_mm(&feet[..2]).unwrap_err();
        assert!(e.contains("2 feet cannot fix a body"), "{e}");
        feet[3][1] = 1e308;
        let e = feet_from_mm(&feet).unwrap_err();
        assert!(e.contains("foot 4") && e.contains("not a foot"), "{e}");
        feet[3][1] = f64::NAN;
        assert!(feet_from_mm(&feet).unwrap_err().contains("foot 4"));
    }
}
