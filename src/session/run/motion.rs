//! The robot's motion, bounded and safe: every wait with a deadline, the
//! stall watch, home and the stop after any failure (HALT, then HOME).

use super::*;

/// Watches the session's own thread for a stall: a loop that wakes every
/// [`StallWatch::PERIOD`] and notes when it did. A gap longer than the plan's
/// limit means the process was stopped or starved; the run must not simply go
/// on from where it was (the robot may have been halted by its watchdog, and
/// an Abort pressed meanwhile could not arrive). The session asks
/// [`StallWatch::check`] before every motion it commands, so that a command
/// queued before the stall is not sent after it, whichever of the two runs
/// first when the thread resumes; a command the stop caught after that check
/// (on its way to the link's task, or queued there) is held back by the UDP
/// client itself once it is older than `udp::client::MOTION_FRESH`.
pub(super) struct StallWatch {
    pub(super) limit: Duration,
    pub(super) last: std::cell::Cell<std::time::Instant>,
}

impl StallWatch {
    pub(super) const PERIOD: Duration = Duration::from_millis(100);

    pub(super) fn new(limit: Duration) -> Self {
        Self {
            limit,
            last: std::cell::Cell::new(std::time::Instant::now()),
        }
    }

    /// Why the run must end, when the thread stalled longer than the limit.
    pub(super) fn stalled(&self) -> Option<String> {
        let gap = self.last.get().elapsed();
        (gap > self.limit).then(|| {
            format!(
                "the service stalled for {:.1} s (more than {:.1} s): the run does not go on from where it stopped",
                gap.as_secs_f64(),
                self.limit.as_secs_f64()
            )
        })
    }

    /// Before a command that moves the robot.
    pub(super) fn check(&self) -> Result<(), SessionError> {
        match self.stalled() {
            Some(why) => Err(SessionError::Aborted(why)),
            None => Ok(()),
        }
    }

    /// Completes, with the reason, when the thread has stalled.
    pub(super) async fn watch(&self) -> String {
        loop {
            tokio::time::sleep(Self::PERIOD).await;
            if let Some(why) = self.stalled() {
                return why;
            }
            self.last.set(std::time::Instant::now());
        }
    }
}

/// Polls the body's state until `done` holds, failing on a fault, a halt
/// nobody asked for, or the deadline. Polling every `plan.poll` (≤ 200 ms)
/// also feeds the lower computer's watchdog.
pub(super) async fn wait_for<C: BodyController>(
    controller: &mut C,
    plan: &Plan,
    deadline: Duration,
    what: &str,
    done: impl Fn(&BodyState) -> bool,
) -> Result<BodyState, SessionError> {
    let start = Instant::now();
    loop {
        let state = controller.state().await.map_err(SessionError::robot)?;
        if done(&state) {
            return Ok(state);
        }
        match state.state {
            MotionState::Fault(code) => {
                return Err(SessionError::Robot {
                    kind: ErrorKind::Refused,
                    message: format!("fault {code} while waiting for {what}"),
                })
            }
            MotionState::Halted => {
                return Err(SessionError::Robot {
                    kind: ErrorKind::Refused,
                    message: format!("the body halted while waiting for {what} (the lower computer's watchdog or its operator)"),
                })
            }
            _ => {}
        }
        if start.elapsed() > deadline {
            return Err(SessionError::Robot {
                kind: ErrorKind::Timeout,
                message: format!(
                    "{what} did not happen within {:.1} s",
                    deadline.as_secs_f64()
                ),
            });
        }
        tokio::time::sleep(plan.poll).await;
    }
}

/// Sends the body home and waits until it stands there; its state then
/// (the home feet).
pub(super) async fn go_home<C: BodyController>(
    controller: &mut C,
    plan: &Plan,
) -> Result<BodyState, SessionError> {
    controller
        .home(millis(plan.motion))
        .await
        .map_err(SessionError::robot)?;
    wait_until_home(controller, plan).await
}

/// The body's state, when the lower computer reports it standing at its
/// home stance with no target (idle); otherwise the refusal of a session that
/// must not move it.
pub(super) async fn standing_at_home<C: BodyController>(
    controller: &mut C,
) -> Result<BodyState, SessionError> {
    let state = controller.state().await.map_err(SessionError::robot)?;
    if state.state == MotionState::Idle {
        return Ok(state);
    }
    Err(SessionError::WouldMove(format!(
        "the lower computer does not report the robot standing at its home stance ({}): a check that moves nothing cannot be made now; it waits for a person to press Check",
        motion_in_words(state.state)
    )))
}

/// A motion state in an operator's words.
pub(super) fn motion_in_words(state: MotionState) -> String {
    match state {
        MotionState::Idle => "at home".into(),
        MotionState::Moving => "moving".into(),
        MotionState::Settled => "holding a pose away from home".into(),
        MotionState::Halted => "halted where it stood".into(),
        MotionState::Fault(code) => format!("fault {code}"),
    }
}

/// Whether the Kinect's motor already stands at the plan's tilt (within a
/// degree), for a session that must not turn it.
pub(super) async fn motor_at_tilt<S: DepthSensor>(
    sensor: &mut S,
    plan: &Plan,
) -> Result<(), SessionError> {
    let reading = tokio::time::timeout(plan.sensor_timeout, sensor.tilt_state()).await;
    let tilt_deg = match reading {
        Ok(Ok(state)) => state.tilt_deg,
        Ok(Err(e)) => {
            return Err(SessionError::WouldMove(format!(
                "the Kinect's motor angle cannot be read ({e}): a check that turns nothing cannot tell whether it stands at the calibration's {:.1}°; it waits for a person to press Check",
                plan.tilt_deg
            )))
        }
        Err(_) => {
            return Err(SessionError::Sensor {
                kind: ErrorKind::Timeout,
                message: format!(
                    "the tilt motor: no answer from the depth sensor in {} s",
                    plan.sensor_timeout.as_secs_f64()
                ),
            })
        }
    };
    if (tilt_deg - plan.tilt_deg).abs() > 1.0 {
        return Err(SessionError::WouldMove(format!(
            "the Kinect's motor stands at {tilt_deg:.1}°, the calibration's tilt is {:.1}°: turning it waits for a person to press Check",
            plan.tilt_deg
        )));
    }
    Ok(())
}

/// Waits until the body reports the home stance (idle).
pub(super) async fn wait_until_home<C: BodyController>(
    controller: &mut C,
    plan: &Plan,
) -> Result<BodyState, SessionError> {
    wait_for(
        controller,
        plan,
        plan.motion_deadline(plan.motion),
        "the home stance",
        |s| s.state == MotionState::Idle,
    )
    .await
}

/// A call to the depth sensor, bounded by `plan.sensor_timeout`: a device
/// that stops answering fails the session (which halts the robot and sends
/// it home) instead of hanging it.
pub(super) async fn bounded<T, E: groundcal_hal::Error>(
    plan: &Plan,
    what: &str,
    call: impl Future<Output = Result<T, E>>,
) -> Result<T, SessionError> {
    match tokio::time::timeout(plan.sensor_timeout, call).await {
        Ok(answer) => answer.map_err(SessionError::sensor),
        Err(_) => Err(SessionError::Sensor {
            kind: ErrorKind::Timeout,
            message: format!(
                "{what}: no answer from the depth sensor in {} s",
                plan.sensor_timeout.as_secs_f64()
            ),
        }),
    }
}

/// Halts the body, then sends it home and waits until it is there. A lower
/// computer that does not answer (the link is down) is tried again, every
/// half second for `plan.link_recovery`: its own watchdog has halted the body
/// meanwhile, and once the link returns the body is sent home. Returns a
/// description of how the robot was left.
pub(super) async fn stop_safely<C: BodyController>(
    controller: &mut C,
    plan: &Plan,
    events: &UnboundedSender<Event>,
) -> (RobotLeft, String) {
    let deadline = tokio::time::Instant::now() + plan.link_recovery;
    let mut retries = 0u32;
    let halted = loop {
        match controller.halt().await {
            Ok(()) => break Ok(()),
            Err(e) if link_down(&e) && tokio::time::Instant::now() < deadline => {
                retries += 1;
                tokio::time::sleep(Duration::from_millis(500)).await;
            }
            Err(e) => break Err(e),
        }
    };
    if let Err(e) = halted {
        return (
            RobotLeft::Unknown,
            format!("could not halt the robot ({e}); check it"),
        );
    }
    let after = if retries > 0 {
        format!(" (the link came back after {retries} more tries)")
    } else {
        String::new()
    };
    send(events, Event::WalkingHome);
    if let Err(e) = controller.home(millis(plan.motion)).await {
        return (
            RobotLeft::Halted,
            format!("halted{after}, but could not send it home ({e})"),
        );
    }
    match wait_until_home(controller, plan).await {
        Ok(_) => (
            RobotLeft::Home,
            format!("halted and sent home{after}; it stands at the home stance"),
        ),
        Err(e) => (
            RobotLeft::Halted,
            format!("halted and sent home{after}, but it did not report the home stance: {e}"),
        ),
    }
}

/// Whether an error says the lower computer did not answer (and may again).
pub(super) fn link_down<E: groundcal_hal::Error>(e: &E) -> bool {
    matches!(e.kind(), ErrorKind::Timeout | ErrorKind::LinkLost)
}
