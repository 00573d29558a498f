//! A lower computer that plays a recorded session back (`groundcal sim-robot
//! --replay DIR`): at each pose it reports the feet the real robot reported
//! there, and it accepts only the poses that were recorded, each exactly as
//! it was commanded. Against it, `groundcal calibrate --sensor replay:DIR`
//! runs the whole live session (link, retransmissions, polling, settle,
//! capture) on what the robot once did, and must find what `groundcal replay
//! DIR` finds.
//!
//! "Exactly" is over the link: SET_POSE carries f32 (`hexapod-udp.md`), so a
//! pose matches when each received value and the recorded one round to the
//! same f32.
//! A pose that does not match, or a pose id the recording does not have, is
//! refused (ACK 2) and counted in [`RecordedTally`]: the upper computer is not
//! doing what it did when the recording was made.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use serde::Serialize;

use crate::controller::{BodyLimits, BodyState, MotionState};
use crate::udp::server::{Body, Refusal};
use groundcal_calib::geometry::PoseDegMm;

/// One recorded pose: what was commanded and the feet reported once settled.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedStance {
    pub commanded: PoseDegMm,
    /// Body frame, mm, foot 1 first.
    pub feet_body_mm: [[f64; 3]; 6],
}

/// A recorded session as the lower computer saw it.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedScript {
    pub home: RecordedStance,
    /// By pose id (never 0: that is home).
    pub poses: BTreeMap<u16, RecordedStance>,
    /// Motions take `duration_ms / time_scale`.
    pub time_scale: f64,
    pub firmware: String,
}

impl RecordedScript {
    /// Limits that admit every recorded pose: the reference simulator's,
    /// widened where the recording went further (a recording from another
    /// robot must still play).
    pub fn limits(&self) -> BodyLimits {
        let mut limits = super::robot::REFERENCE_LIMITS;
        for stance in std::iter::once(&self.home).chain(self.poses.values()) {
            let p = &stance.commanded;
            let tilt = p
                .alpha_deg
                .abs()
                .max(p.beta_deg.abs())
                .max(p.gamma_deg.abs());
            limits.max_tilt_deg = limits.max_tilt_deg.max(tilt.ceil());
            limits.min_height_mm = limits.min_height_mm.min(p.py_mm.floor());
            limits.max_height_mm = limits.max_height_mm.max(p.py_mm.ceil());
            let shift = p.px_mm.abs().max(p.pz_mm.abs());
            limits.max_shift_mm = limits.max_shift_mm.max(shift.ceil());
        }
        limits
    }
}

/// What the upper computer asked of the recorded robot.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct RecordedTally {
    /// Pose ids accepted, in the order their SET_POSE was acted on.
    pub accepted: Vec<u16>,
    /// SET_POSEs refused because they were not as recorded, each explained.
    pub mismatches: Vec<String>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    Idle,
    Moving { until: Instant, to_home: bool },
    Settled,
    Halted,
}

/// The recorded robot: motion is only a timer, feet come from the script.
#[derive(Debug)]
pub struct RecordedRobot {
    script: RecordedScript,
    /// Announced in WELCOME and checked at every SET_POSE: worked out once.
    limits: BodyLimits,
    epoch: Instant,
    phase: Phase,
    /// The pose the feet are reported for (0: home).
    stance: u16,
    /// The last accepted target (0: home).
    pose_id: u16,
    tally: RecordedTally,
}

impl RecordedRobot {
    /// Standing at the recorded home stance at `now`.
    pub fn new(script: RecordedScript, now: Instant) -> Self {
        Self {
            limits: script.limits(),
            script,
            epoch: now,
            phase: Phase::Idle,
            stance: 0,
            pose_id: 0,
            tally: RecordedTally::default(),
        }
    }

    /// What was asked so far.
    pub fn tally(&self) -> &RecordedTally {
        &self.tally
    }

    /// Brings the motion up to `now`.
    pub fn advance(&mut self, now: Instant) {
        if let Phase::Moving { until, to_home } = self.phase {
            if now >= until {
                self.stance = self.pose_id;
                self.phase = if to_home { Phase::Idle } else { Phase::Settled };
            }
        }
    }

    /// A restart: stops where it is and forgets the target.
    pub fn restart(&mut self, now: Instant) {
        self.advance(now);
        self.phase = Phase::Halted;
        self.pose_id = 0;
    }

    fn start(&mut self, pose_id: u16, duration_ms: u32, now: Instant) {
        let seconds = f64::from(duration_ms) / 1000.0 / self.script.time_scale;
        let duration = Duration::try_from_secs_f64(seconds).unwrap_or(Duration::ZERO);
        self.pose_id = pose_id;
        self.phase = Phase::Moving {
            until: now + duration,
            to_home: pose_id == 0,
        };
        self.advance(now);
    }

    fn feet(&self) -> [[f64; 3]; 6] {
        match self.stance {
            0 => self.script.home.feet_body_mm,
            id => self
                .script
                .poses
                .get(&id)
                .map_or(self.script.home.feet_body_mm, |s| s.feet_body_mm),
        }
    }
}

/// Why `received` is not `recorded` as an f32 link carries them, if it is not.
fn difference(recorded: &PoseDegMm, received: &PoseDegMm) -> Option<String> {
    let pairs = [
        ("alpha_deg", recorded.alpha_deg, received.alpha_deg),
        ("beta_deg", recorded.beta_deg, received.beta_deg),
        ("gamma_deg", recorded.gamma_deg, received.gamma_deg),
        ("px_mm", recorded.px_mm, received.px_mm),
        ("py_mm", recorded.py_mm, received.py_mm),
        ("pz_mm", recorded.pz_mm, received.pz_mm),
    ];
    let differing: Vec<String> = pairs
        .iter()
        .filter(|(_, a, b)| *a as f32 != *b as f32)
        .map(|(name, a, b)| format!("{name} {b} (recorded {a})"))
        .collect();
    (!differing.is_empty()).then(|| differing.join(", "))
}

impl Body for RecordedRobot {
    fn limits(&self) -> BodyLimits {
        self.limits
    }

    fn firmware(&self) -> String {
        self.script.firmware.clone()
    }

    fn set_pose(
        &mut self,
        pose_id: u16,
        pose: &PoseDegMm,
        duration_ms: u32,
        now: Instant,
    ) -> Result<(), Refusal> {
        self.advance(now);
        let Some(recorded) = self.script.poses.get(&pose_id) else {
            self.tally
                .mismatches
                .push(format!("pose {pose_id}: not in the recording"));
            return Err(Refusal);
        };
        if let Some(why) = difference(&recorded.commanded, pose) {
            self.tally.mismatches.push(format!("pose {pose_id}: {why}"));
            return Err(Refusal);
        }
        self.tally.accepted.push(pose_id);
        self.start(pose_id, duration_ms, now);
        Ok(())
    }

    fn home(&mut self, duration_ms: u32, now: Instant) -> Result<(), Refusal> {
        self.advance(now);
        self.start(0, duration_ms, now);
        Ok(())
    }

    fn halt(&mut self, now: Instant) {
        self.advance(now);
        self.phase = Phase::Halted;
    }

    fn state(&mut self, now: Instant) -> BodyState {
        let state = self.motion(now);
        BodyState {
            state,
            pose_id: self.pose_id,
            time_us: u64::try_from(now.saturating_duration_since(self.epoch).as_micros())
                .unwrap_or(u64::MAX),
            feet_mm: self.feet(),
        }
    }

    fn motion(&mut self, now: Instant) -> MotionState {
        self.advance(now);
        match self.phase {
            Phase::Idle => MotionState::Idle,
            Phase::Moving { .. } => MotionState::Moving,
            Phase::Settled => MotionState::Settled,
            Phase::Halted => MotionState::Halted,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stance(py_mm: f64, foot_y: f64) -> RecordedStance {
        RecordedStance {
            commanded: PoseDegMm {
                alpha_deg: 0.1,
                beta_deg: -3.3,
                gamma_deg: 0.0,
                px_mm: 0.0,
                py_mm,
                pz_mm: 0.0,
            },
            feet_body_mm: [[100.0, foot_y, 0.0]; 6],
        }
    }

    fn script() -> RecordedScript {
        RecordedScript {
            home: stance(600.0, -600.0),
            poses: BTreeMap::from([(1, stance(650.0, -650.0)), (2, stance(900.0, -900.0))]),
            time_scale: 1.0,
            firmware: "replay".into(),
        }
    }

    #[test]
    fn reports_the_recorded_feet_once_settled_and_refuses_other_poses() {
        let t0 = Instant::now();
        let mut robot = RecordedRobot::new(script(), t0);
        assert_eq!(robot.state(t0).feet_mm[0][1], -600.0);
        let one = script().poses[&1].commanded;
        robot.set_pose(1, &one, 1000, t0).unwrap();
        let moving = robot.state(t0 + Duration::from_millis(500));
        assert_eq!(moving.state, MotionState::Moving);
        assert_eq!(
            moving.feet_mm[0][1], -600.0,
            "no recorded feet before settling"
        );
        let settled = robot.state(t0 + Duration::from_millis(1000));
        assert_eq!((settled.state, settled.pose_id), (MotionState::Settled, 1));
        assert_eq!(settled.feet_mm[0][1], -650.0);

        // Through f32, the recorded pose still matches; anything else does not.
        let via_f32 = PoseDegMm {
            alpha_deg: f64::from(0.1f32),
            ..one
        };
        assert!(robot.set_pose(1, &via_f32, 10, t0).is_ok());
        let off = PoseDegMm {
            beta_deg: -3.4,
            ..one
        };
        assert_eq!(robot.set_pose(1, &off, 10, t0), Err(Refusal));
        assert_eq!(robot.set_pose(7, &one, 10, t0), Err(Refusal));
        assert_eq!(robot.tally().accepted, vec![1, 1]);
        assert_eq!(robot.tally().mismatches.len(), 2);
        assert!(robot.tally().mismatches[0].contains("beta_deg"));
        assert!(robot.tally().mismatches[1].contains("not in the recording"));
    }

    #[test]
    fn limits_widen_to_admit_the_recording() {
        let limits = script().limits();
        assert_eq!(limits.max_height_mm, 900.0);
        assert_eq!(limits.min_height_mm, 500.0);
        assert_eq!(limits.max_tilt_deg, 25.0);
    }
}
