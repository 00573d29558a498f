//! The simulated hexapod: the lower computer's body, as `groundcal sim-robot`
//! serves it over UDP ([`crate::sim::lower_computer`]) and as `--robot sim` uses it
//! in process ([`SimBodyController`]).
//!
//! The body moves from its pose to the commanded one in the commanded
//! duration divided by the time scale, then holds still. Its *true* pose is
//! not the commanded one: it is the commanded `ground_from_robot` composed
//! with a fixed per-robot offset (a few tenths of a degree and a few
//! millimetres, drawn from the seed: manufacturing and installation errors)
//! and a small random error per pose. The six feet stay planted on the
//! ground; each STATE reports them in the body frame from the true pose,
//! `feet_body = robot_from_ground(true) · feet_ground`, with ~0.1 mm of noise
//! (the same at every report of one pose), as forward kinematics of measured
//! joints would. The true pose is written
//! into a [`TruePose`] for the simulated Kinect, and nowhere else.

use std::time::{Duration, Instant};

use nalgebra::{Point3, Vector3, Vector6};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::TruePose;
use crate::controller::{BodyController, BodyLimits, BodyState, MotionState, Welcome};
use crate::error::{Error, ErrorKind};
use crate::udp::proto::AckStatus;
use crate::udp::server::{check_pose, Body, Refusal};
use groundcal_calib::geometry::{PoseDegMm, PoseParams, Transform};

/// The reference simulator's limits (`hexapod-udp.md`).
pub const REFERENCE_LIMITS: BodyLimits = BodyLimits {
    max_tilt_deg: 25.0,
    min_height_mm: 500.0,
    max_height_mm: 800.0,
    max_shift_mm: 100.0,
};

/// The reference home stance: level, the body 600 mm above the ground.
pub const REFERENCE_HOME: PoseDegMm = PoseDegMm {
    alpha_deg: 0.0,
    beta_deg: 0.0,
    gamma_deg: 0.0,
    px_mm: 0.0,
    py_mm: 600.0,
    pz_mm: 0.0,
};

/// The six feet on the ground (ground frame, mm), foot 1 first: a hexagon
/// like the Octopus's (`shared/data/sample-12`'s home feet).
pub const REFERENCE_FEET_GROUND_MM: [[f64; 3]; 6] = [
    [693.0, 0.0, 400.0],
    [0.0, 0.0, 800.0],
    [-693.0, 0.0, 400.0],
    [-693.0, 0.0, -400.0],
    [0.0, 0.0, -800.0],
    [693.0, 0.0, -400.0],
];

/// What the simulated lower computer announces in WELCOME.
pub const FIRMWARE: &str = "groundcal-sim 1";

/// How the simulated robot is built.
#[derive(Debug, Clone, PartialEq)]
pub struct SimRobotConfig {
    /// Draws the fixed offset, the per-pose errors and the feet noise.
    pub seed: u64,
    /// Motions take `duration_ms / time_scale` (50: fifty times faster).
    pub time_scale: f64,
    pub limits: BodyLimits,
    /// The commanded home stance.
    pub home: PoseDegMm,
    pub feet_ground_mm: [[f64; 3]; 6],
    /// The fixed offset's bound per angle (uniform in ±this).
    pub offset_max_deg: f64,
    /// The fixed offset's bound per axis (uniform in ±this).
    pub offset_max_mm: f64,
    /// Standard deviation of the random error per pose, per angle.
    pub per_pose_sigma_deg: f64,
    /// Standard deviation of the random error per pose, per axis.
    pub per_pose_sigma_mm: f64,
    /// Standard deviation of each reported foot coordinate.
    pub feet_noise_mm: f64,
    pub firmware: String,
    /// A foot that sinks into soft ground, if one does.
    pub sinking_foot: Option<SinkingFoot>,
}

/// A foot that sinks into soft ground once the body has been sent to a pose
/// (and stays sunk): the feet are no longer where they were planted, which
/// the calibration must notice and work around.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SinkingFoot {
    /// Which foot, 1–6.
    pub foot: usize,
    /// The first pose id at which it has sunk.
    pub from_pose: u16,
    /// How far it sinks, mm.
    pub depth_mm: f64,
}

impl SimRobotConfig {
    /// The reference simulator of `hexapod-udp.md`.
    pub fn reference(seed: u64, time_scale: f64) -> Self {
        Self {
            seed,
            time_scale,
            limits: REFERENCE_LIMITS,
            home: REFERENCE_HOME,
            feet_ground_mm: REFERENCE_FEET_GROUND_MM,
            offset_max_deg: 0.4,
            offset_max_mm: 4.0,
            per_pose_sigma_deg: 0.02,
            per_pose_sigma_mm: 0.2,
            feet_noise_mm: 0.1,
            firmware: FIRMWARE.to_string(),
            sinking_foot: None,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    /// At home, no target.
    Idle,
    Moving {
        from: PoseParams,
        to: PoseParams,
        start: Instant,
        duration: Duration,
    },
    Settled,
    Halted,
    Fault(u8),
}

/// A standard normal draw (Box-Muller).
fn standard_normal(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.gen_range(f64::EPSILON..1.0);
    let u2: f64 = rng.gen();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// The simulated body. Time is passed in, so that it runs on any clock.
#[derive(Debug)]
pub struct SimRobot {
    config: SimRobotConfig,
    rng: ChaCha8Rng,
    /// The fixed kinematic error: `true = commanded · offset · random`.
    offset: Transform,
    true_pose: TruePose,
    epoch: Instant,
    phase: Phase,
    /// The true `ground_from_robot` when not moving.
    resting: PoseParams,
    /// The last accepted target (0 = home).
    pose_id: u16,
    /// Whether the motion in progress (or finished) goes home.
    target_is_home: bool,
    /// Whether the sinking foot has sunk.
    sunk: bool,
}

impl SimRobot {
    /// A robot standing at its home stance at `now`; its true pose is written
    /// to `true_pose` from then on.
    pub fn new(config: SimRobotConfig, true_pose: TruePose, now: Instant) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
        let mut uniform = |bound: f64| rng.gen_range(-1.0..=1.0) * bound;
        let offset = PoseParams::new(
            uniform(config.offset_max_deg).to_radians(),
            uniform(config.offset_max_deg).to_radians(),
            uniform(config.offset_max_deg).to_radians(),
            Vector3::new(
                uniform(config.offset_max_mm),
                uniform(config.offset_max_mm),
                uniform(config.offset_max_mm),
            ) / 1000.0,
        )
        .to_transform();
        let mut robot = Self {
            config,
            rng,
            offset,
            true_pose,
            epoch: now,
            phase: Phase::Idle,
            resting: PoseParams::identity(),
            pose_id: 0,
            target_is_home: true,
            sunk: false,
        };
        let home = robot.config.home;
        robot.resting = robot.true_from_commanded(&home);
        robot.true_pose.set(robot.resting.to_transform());
        robot
    }

    pub fn config(&self) -> &SimRobotConfig {
        &self.config
    }

    /// The fixed kinematic offset (`commanded⁻¹ · true` without the per-pose
    /// part), for tests: the calibration must not need it.
    pub fn kinematic_offset(&self) -> PoseDegMm {
        PoseDegMm::from_params(&PoseParams::from_transform(&self.offset))
    }

    /// The true `ground_from_robot` at `now`.
    pub fn true_pose_at(&mut self, now: Instant) -> PoseParams {
        self.advance(now);
        self.pose_at(now)
    }

    /// Brings the motion up to `now` and publishes the true pose.
    pub fn advance(&mut self, now: Instant) {
        if let Phase::Moving {
            to,
            start,
            duration,
            ..
        } = self.phase
        {
            if now.saturating_duration_since(start) >= duration {
                self.resting = to;
                self.phase = if self.target_is_home {
                    Phase::Idle
                } else {
                    Phase::Settled
                };
            }
        }
        self.true_pose.set(self.pose_at(now).to_transform());
    }

    fn pose_at(&self, now: Instant) -> PoseParams {
        match self.phase {
            Phase::Moving {
                from,
                to,
                start,
                duration,
            } => {
                let u = if duration.is_zero() {
                    1.0
                } else {
                    (now.saturating_duration_since(start).as_secs_f64() / duration.as_secs_f64())
                        .min(1.0)
                };
                // Smooth start and stop, as a trajectory planner would.
                let s = u * u * (3.0 - 2.0 * u);
                let v: Vector6<f64> = from.to_vector() * (1.0 - s) + to.to_vector() * s;
                PoseParams::from_vector(&v)
            }
            _ => self.resting,
        }
    }

    fn motion_state(&self) -> MotionState {
        match self.phase {
            Phase::Idle => MotionState::Idle,
            Phase::Moving { .. } => MotionState::Moving,
            Phase::Settled => MotionState::Settled,
            Phase::Halted => MotionState::Halted,
            Phase::Fault(code) => MotionState::Fault(code),
        }
    }

    /// `true = commanded · offset · random`, the random part drawn anew.
    fn true_from_commanded(&mut self, commanded: &PoseDegMm) -> PoseParams {
        let deg = self.config.per_pose_sigma_deg;
        let mm = self.config.per_pose_sigma_mm;
        let random = PoseParams::new(
            (self.normal() * deg).to_radians(),
            (self.normal() * deg).to_radians(),
            (self.normal() * deg).to_radians(),
            Vector3::new(self.normal() * mm, self.normal() * mm, self.normal() * mm) / 1000.0,
        )
        .to_transform();
        let ground_from_robot = commanded.to_params().to_transform() * self.offset * random;
        PoseParams::from_transform(&ground_from_robot)
    }

    /// A standard normal draw (Box-Muller).
    fn normal(&mut self) -> f64 {
        standard_normal(&mut self.rng)
    }

    fn scaled(&self, duration_ms: u32) -> Duration {
        let seconds = f64::from(duration_ms) / 1000.0 / self.config.time_scale;
        Duration::try_from_secs_f64(seconds).unwrap_or(Duration::ZERO)
    }

    fn start_motion(&mut self, to: PoseParams, duration_ms: u32, now: Instant) {
        let from = self.pose_at(now);
        self.phase = Phase::Moving {
            from,
            to,
            start: now,
            duration: self.scaled(duration_ms),
        };
        self.advance(now);
    }

    /// A lower computer restart: the motion stops where the body is, and
    /// nothing is remembered of the target.
    pub fn restart(&mut self, now: Instant) {
        self.advance(now);
        self.resting = self.pose_at(now);
        self.phase = Phase::Halted;
        self.pose_id = 0;
        self.target_is_home = false;
        self.advance(now);
    }

    /// Puts the body in a fault state (tests of ACK 2).
    pub fn inject_fault(&mut self, code: u8, now: Instant) {
        self.advance(now);
        self.resting = self.pose_at(now);
        self.phase = Phase::Fault(code.max(1));
    }

    /// The feet as reported: the true feet in the body frame, with noise that
    /// is the same at every report of one pose (as a joint encoder's error
    /// is for one stance). Drawn from its own generator, keyed by the seed
    /// and the pose, so that how often the feet are asked for does not change
    /// any other draw: a simulated calibration is the same however its polls
    /// fall in time.
    fn feet_body_mm(&mut self, ground_from_robot: &Transform) -> [[f64; 3]; 6] {
        let robot_from_ground = ground_from_robot.inverse();
        let key = (u64::from(self.pose_id) << 1) | u64::from(self.target_is_home);
        let mut noise_rng = ChaCha8Rng::seed_from_u64(
            self.config.seed ^ 0x0fee_7000_0000_0000 ^ key.wrapping_mul(0x9e37_79b9_7f4a_7c15),
        );
        let mut feet = [[0.0; 3]; 6];
        let mut feet_ground = self.config.feet_ground_mm;
        if let Some(sinking) = self.config.sinking_foot.filter(|_| self.sunk) {
            if let Some(foot) = sinking
                .foot
                .checked_sub(1)
                .and_then(|i| feet_ground.get_mut(i))
            {
                foot[1] -= sinking.depth_mm;
            }
        }
        for (out, ground) in feet.iter_mut().zip(feet_ground) {
            let p = robot_from_ground * Point3::from(Vector3::from(ground) / 1000.0);
            for (o, v) in out.iter_mut().zip(p.coords.iter()) {
                *o = v * 1000.0 + standard_normal(&mut noise_rng) * self.config.feet_noise_mm;
            }
        }
        feet
    }
}

impl Body for SimRobot {
    fn limits(&self) -> BodyLimits {
        self.config.limits
    }

    fn firmware(&self) -> String {
        self.config.firmware.clone()
    }

    fn set_pose(
        &mut self,
        pose_id: u16,
        pose: &PoseDegMm,
        duration_ms: u32,
        now: Instant,
    ) -> Result<(), Refusal> {
        self.advance(now);
        if let Phase::Fault(_) = self.phase {
            return Err(Refusal);
        }
        let to = self.true_from_commanded(pose);
        self.pose_id = pose_id;
        if let Some(sinking) = self.config.sinking_foot {
            self.sunk |= pose_id >= sinking.from_pose;
        }
        self.target_is_home = false;
        self.start_motion(to, duration_ms, now);
        Ok(())
    }

    fn home(&mut self, duration_ms: u32, now: Instant) -> Result<(), Refusal> {
        self.advance(now);
        if let Phase::Fault(_) = self.phase {
            return Err(Refusal);
        }
        let home = self.config.home;
        let to = self.true_from_commanded(&home);
        self.pose_id = 0;
        self.target_is_home = true;
        self.start_motion(to, duration_ms, now);
        Ok(())
    }

    fn halt(&mut self, now: Instant) {
        self.advance(now);
        if let Phase::Fault(_) = self.phase {
            return;
        }
        self.resting = self.pose_at(now);
        self.phase = Phase::Halted;
        self.advance(now);
    }

    fn state(&mut self, now: Instant) -> BodyState {
        self.advance(now);
        let ground_from_robot = self.pose_at(now).to_transform();
        BodyState {
            state: self.motion_state(),
            pose_id: self.pose_id,
            time_us: u64::try_from(now.saturating_duration_since(self.epoch).as_micros())
                .unwrap_or(u64::MAX),
            feet_mm: self.feet_body_mm(&ground_from_robot),
        }
    }

    fn motion(&mut self, now: Instant) -> MotionState {
        self.advance(now);
        self.motion_state()
    }
}

/// Why the in-process simulated robot refused a request.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("the simulated robot refused {request}: {status}{detail}")]
pub struct SimError {
    pub request: &'static str,
    pub status: AckStatus,
    /// More words, e.g. which limit.
    pub detail: String,
}

impl Error for SimError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Refused
    }
}

/// `--robot sim`: the simulated robot in process, without UDP. It answers
/// as the simulated lower computer would (limits, ACK 2 in a fault), on
/// tokio's clock, so that tests can pause and advance time. There is no
/// watchdog: there is no link to lose.
#[derive(Debug)]
pub struct SimBodyController {
    robot: SimRobot,
    sessions: ChaCha8Rng,
    session: u32,
}

impl SimBodyController {
    /// A simulated robot at its home stance, writing its true pose to
    /// `true_pose`.
    pub fn new(config: SimRobotConfig, true_pose: TruePose) -> Self {
        let sessions = ChaCha8Rng::seed_from_u64(config.seed ^ 0x5e55_1017);
        Self {
            robot: SimRobot::new(config, true_pose, now()),
            sessions,
            session: 0,
        }
    }

    /// The simulated body, for tests.
    pub fn robot(&mut self) -> &mut SimRobot {
        &mut self.robot
    }

    fn refused(request: &'static str, status: AckStatus, detail: String) -> SimError {
        SimError {
            request,
            status,
            detail,
        }
    }
}

fn now() -> Instant {
    tokio::time::Instant::now().into_std()
}

impl BodyController for SimBodyController {
    type Error = SimError;

    async fn hello(&mut self) -> Result<Welcome, SimError> {
        let previous = self.session;
        self.session = loop {
            let s: u32 = self.sessions.gen();
            if s != 0 && s != previous {
                break s;
            }
        };
        Ok(Welcome {
            session: self.session,
            limits: self.robot.limits(),
            firmware: self.robot.firmware(),
        })
    }

    async fn set_pose(
        &mut self,
        pose_id: u16,
        pose: &PoseDegMm,
        duration_ms: u32,
    ) -> Result<(), SimError> {
        check_pose(&self.robot.limits(), pose)
            .map_err(|r| Self::refused("SET_POSE", r.status(), format!(": {r}")))?;
        self.robot
            .set_pose(pose_id, pose, duration_ms, now())
            .map_err(|Refusal| Self::refused("SET_POSE", AckStatus::RefusedInState, String::new()))
    }

    async fn state(&mut self) -> Result<BodyState, SimError> {
        Ok(self.robot.state(now()))
    }

    async fn home(&mut self, duration_ms: u32) -> Result<(), SimError> {
        self.robot
            .home(duration_ms, now())
            .map_err(|Refusal| Self::refused("HOME", AckStatus::RefusedInState, String::new()))
    }

    async fn halt(&mut self) -> Result<(), SimError> {
        self.robot.halt(now());
        Ok(())
    }

    async fn bye(&mut self) -> Result<(), SimError> {
        self.session = 0;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(beta_deg: f64, gamma_deg: f64, py_mm: f64) -> PoseDegMm {
        PoseDegMm {
            alpha_deg: 0.0,
            beta_deg,
            gamma_deg,
            px_mm: 0.0,
            py_mm,
            pz_mm: 0.0,
        }
    }

    fn robot(seed: u64) -> (SimRobot, TruePose, Instant) {
        let true_pose = TruePose::new(Transform::identity());
        let t0 = Instant::now();
        let robot = SimRobot::new(SimRobotConfig::reference(seed, 1.0), true_pose.clone(), t0);
        (robot, true_pose, t0)
    }

    /// Distance between two poses: degrees and millimetres.
    fn difference(a: &PoseParams, b: &PoseParams) -> (f64, f64) {
        let delta = a.to_transform().inverse() * b.to_transform();
        (
            delta.rotation.angle().to_degrees(),
            delta.translation.vector.norm() * 1000.0,
        )
    }

    #[test]
    fn moves_in_the_scaled_duration_then_settles() {
        let true_pose = TruePose::new(Transform::identity());
        let t0 = Instant::now();
        let mut r = SimRobot::new(SimRobotConfig::reference(1, 50.0), true_pose, t0);
        assert_eq!(r.state(t0).state, MotionState::Idle);
        r.set_pose(7, &pose(10.0, 5.0, 650.0), 2000, t0).unwrap();
        let ms = |n| t0 + Duration::from_millis(n);
        assert_eq!(r.state(ms(39)).state, MotionState::Moving);
        let settled = r.state(ms(40));
        assert_eq!((settled.state, settled.pose_id), (MotionState::Settled, 7));
        r.home(2000, ms(50)).unwrap();
        assert_eq!(r.state(ms(60)).state, MotionState::Moving);
        let home = r.state(ms(90));
        assert_eq!((home.state, home.pose_id), (MotionState::Idle, 0));
    }

    #[test]
    fn the_true_pose_differs_from_the_commanded_one_by_a_small_error() {
        let (mut r, true_pose, t0) = robot(3);
        let commanded = pose(15.0, 12.0, 631.0);
        r.set_pose(1, &commanded, 0, t0).unwrap();
        r.advance(t0);
        let truth = PoseParams::from_transform(&true_pose.get());
        let (deg, mm) = difference(&commanded.to_params(), &truth);
        assert!(deg > 0.01 && deg < 1.0, "{deg}°");
        assert!(mm > 0.1 && mm < 15.0, "{mm} mm");
        // The fixed part is the same for every pose, the random part is small.
        let offset = r.kinematic_offset().to_params().to_transform();
        let without_random = commanded.to_params().to_transform() * offset;
        let (deg, mm) = difference(&PoseParams::from_transform(&without_random), &truth);
        assert!(deg < 0.15 && mm < 1.5, "{deg}° {mm} mm");
        // Another robot, another offset.
        let (other, _, _) = robot(4);
        assert_ne!(other.kinematic_offset(), r.kinematic_offset());
    }

    #[test]
    fn feet_stay_planted_on_the_ground() {
        let (mut r, true_pose, t0) = robot(5);
        let home = r.state(t0);
        for (foot, ground) in home.feet_mm.iter().zip(REFERENCE_FEET_GROUND_MM) {
            // About 600 mm below a nearly level body.
            assert!((foot[1] + 600.0).abs() < 20.0, "{foot:?}");
            assert!((foot[0] - ground[0]).abs() < 20.0 && (foot[2] - ground[2]).abs() < 20.0);
        }
        r.set_pose(2, &pose(-19.0, -8.0, 641.0), 1000, t0).unwrap();
        for ms in [0, 300, 700, 1200] {
            let now = t0 + Duration::from_millis(ms);
            let state = r.state(now);
            let ground_from_robot = true_pose.get();
            for (foot, ground) in state.feet_mm.iter().zip(REFERENCE_FEET_GROUND_MM) {
                let back = ground_from_robot * Point3::from(Vector3::from(*foot) / 1000.0);
                let error = (back.coords * 1000.0 - Vector3::from(ground)).norm();
                assert!(error < 1.0, "{ms} ms: foot off its spot by {error} mm");
            }
        }
    }

    #[test]
    fn halt_stops_mid_motion_and_a_new_target_replaces_the_old() {
        let (mut r, true_pose, t0) = robot(6);
        let ms = |n| t0 + Duration::from_millis(n);
        r.set_pose(1, &pose(20.0, 0.0, 700.0), 1000, t0).unwrap();
        r.halt(ms(500));
        let halted = r.state(ms(600));
        assert_eq!((halted.state, halted.pose_id), (MotionState::Halted, 1));
        let stopped = true_pose.get();
        r.advance(ms(2000));
        assert_eq!(true_pose.get(), stopped, "a halted body stays");
        r.set_pose(2, &pose(0.0, 10.0, 650.0), 1000, ms(2000))
            .unwrap();
        r.set_pose(3, &pose(0.0, -10.0, 650.0), 1000, ms(2500))
            .unwrap();
        assert_eq!(r.state(ms(3400)).state, MotionState::Moving);
        let done = r.state(ms(3500));
        assert_eq!((done.state, done.pose_id), (MotionState::Settled, 3));
    }

    #[test]
    fn faults_refuse_motion() {
        let (mut r, _, t0) = robot(7);
        r.inject_fault(9, t0);
        assert_eq!(r.set_pose(1, &pose(0.0, 0.0, 600.0), 100, t0), Err(Refusal));
        assert_eq!(r.home(100, t0), Err(Refusal));
        r.halt(t0);
        assert_eq!(r.state(t0).state, MotionState::Fault(9));
    }

    #[tokio::test(start_paused = true)]
    async fn sim_controller_runs_on_tokio_time() {
        let true_pose = TruePose::new(Transform::identity());
        let mut c = SimBodyController::new(SimRobotConfig::reference(8, 10.0), true_pose);
        let welcome = c.hello().await.unwrap();
        assert_eq!(welcome.limits, REFERENCE_LIMITS);
        assert_eq!(welcome.firmware, FIRMWARE);
        c.set_pose(4, &pose(5.0, 5.0, 650.0), 1000).await.unwrap();
        assert_eq!(c.state().await.unwrap().state, MotionState::Moving);
        tokio::time::sleep(Duration::from_millis(100)).await;
        let s = c.state().await.unwrap();
        assert_eq!((s.state, s.pose_id), (MotionState::Settled, 4));
        let e = c
            .set_pose(5, &pose(30.0, 0.0, 650.0), 1000)
            .await
            .unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Refused);
        assert_eq!(e.status, AckStatus::OutsideLimits);
        assert!(e.to_string().contains("beta"), "{e}");
    }
}
