//! The poses' ground fits on worker threads (their frames kept for a second
//! fit), the provisional solves the page shows, and the end: the solve and
//! verdict of a calibration, or a check's comparison.

use super::*;

/// Most frames a calibration keeps for a second fit of the ground (about
/// 0.2 MB each, compressed: 130 MB; the robot's 52 poses of 3 frames keep
/// 156, about 33 MB).
pub(super) const MOST_KEPT_FRAMES: usize = 600;

/// A pose whose ground is being fitted on a worker thread.
pub(super) struct PendingFit {
    pub(super) index: u16,
    /// The body pose from the feet, when they fixed it.
    pub(super) ground_from_robot: Option<Transform>,
    pub(super) gravity: Option<GravityReading>,
    /// The body pose, for a second fit of the frames.
    pub(super) body: Option<BodyEstimate>,
    pub(super) handle: JoinHandle<(Result<Observation, String>, Option<KeptFrames>)>,
    /// The fit's outcome once it has been awaited (a handle is awaited once).
    pub(super) done: Option<Result<Observation, String>>,
    /// The frames, kept for a second fit when calibrating.
    pub(super) frames: Option<KeptFrames>,
}

impl PendingFit {
    pub(super) async fn outcome(&mut self) -> &Result<Observation, String> {
        if self.done.is_none() {
            let outcome = match (&mut self.handle).await {
                Ok((outcome, frames)) => {
                    self.frames = frames;
                    outcome
                }
                Err(e) => Err(format!("the fit failed: {e}")),
            };
            self.done = Some(outcome);
        }
        self.done
            .get_or_insert_with(|| Err("the fit was lost".into()))
    }
}

/// Fits the ground of a pose from its frames (on a blocking worker), and
/// shows what the camera saw with the ground it chose.
pub(super) fn fit_pose(
    processor: Arc<PoseObserver>,
    index: u16,
    body: BodyEstimate,
    frames: Vec<DepthFrame>,
    events: UnboundedSender<Event>,
    keep_frames: bool,
) -> (Result<Observation, String>, Option<KeptFrames>) {
    let raw: Vec<&[u16]> = frames.iter().map(|f| f.raw.as_slice()).collect();
    let fitted = processor
        .observe_with_fit(u32::from(index), &body, &raw, &mut FitBuffers::default())
        .map_err(|e| format!("no ground found: {e}"));
    if let Some(frame) = raw.first() {
        let fit = fitted.as_ref().map(|(_, fit)| fit).map_err(String::as_str);
        let view = GroundView::of(frame, processor.camera(), fit);
        send(
            &events,
            Event::GroundSeen {
                index: Some(index),
                view: Box::new(view),
            },
        );
    }
    let kept = (keep_frames && fitted.is_ok()).then(|| KeptFrames::keep(&frames));
    (fitted.map(|(observation, _)| observation), kept)
}

/// The fewest fitted poses a provisional solve is tried on: below that the
/// six parameters are not all observable by any schedule.
pub(super) const PROVISIONAL_MIN_POSES: usize = 6;

/// Solves over the poses fitted so far and reports θ and e_d per pose (about
/// a millisecond for 52 poses, more on a busy robot computer; a schedule
/// that does not pin every parameter down yet gives nothing). The solve runs
/// on tokio's blocking pool: the session's thread keeps its stall watch
/// ticking and stays free for an Abort.
pub(super) async fn report_provisional(
    pending: &[PendingFit],
    plan: &Plan,
    events: &UnboundedSender<Event>,
) {
    let observations: Vec<Observation> = pending
        .iter()
        .filter_map(|fit| fit.done.as_ref()?.as_ref().ok().cloned())
        .collect();
    if observations.len() < PROVISIONAL_MIN_POSES {
        return;
    }
    let settings = plan.calibration.solve;
    let solved = tokio::task::spawn_blocking(move || {
        let calibration = crate::calib::solve::solve(&observations, &settings).ok()?;
        let poses: Vec<ProvisionalPose> = calibration
            .poses
            .iter()
            .map(|p| ProvisionalPose {
                index: u16::try_from(p.index).unwrap_or(u16::MAX),
                theta_deg: p.theta.to_degrees(),
                e_d_mm: p.e_d * 1000.0,
                used: p.used,
            })
            .collect();
        Some(poses)
    })
    .await;
    // Sent here, not from the worker: a run that ended while it solved
    // (a stall, an Abort) has dropped this future, and says nothing after.
    match solved {
        Ok(Some(poses)) => send(events, Event::Provisional { poses }),
        Ok(None) => {}
        Err(e) => tracing::warn!("the provisional solve failed: {e}"),
    }
}

/// Reports the fits that have finished, in pose order; after new ones
/// (while poses are still being visited), a provisional solve.
pub(super) async fn report_finished(
    pending: &mut [PendingFit],
    reported: &mut usize,
    of: usize,
    events: &UnboundedSender<Event>,
    all: bool,
    plan: &Plan,
) {
    let before = *reported;
    while let Some(fit) = pending.get_mut(*reported) {
        if !all && !fit.handle.is_finished() {
            break;
        }
        let outcome = match fit.outcome().await {
            Ok(o) => Ok(PoseFit {
                inliers: o.inliers.unwrap_or(0),
                plane: [
                    o.plane.normal.x,
                    o.plane.normal.y,
                    o.plane.normal.z,
                    o.plane.d,
                ],
            }),
            Err(e) => Err(e.clone()),
        };
        send(
            events,
            Event::PoseDone {
                index: fit.index,
                of,
                outcome,
            },
        );
        *reported += 1;
    }
    if !all && *reported > before && plan.calibrating {
        report_provisional(pending, plan, events).await;
    }
}

/// What visiting the poses gave.
pub(super) struct Visited {
    /// The lower computer's firmware, as its WELCOME said.
    pub(super) firmware: String,
    pub(super) poses: Vec<VisitedPose>,
    /// Per pose that gave a plane when calibrating: its place in `poses`,
    /// its body pose and its frames, for a second fit.
    pub(super) kept: Vec<(usize, BodyEstimate, KeptFrames)>,
    /// What fitted the poses.
    pub(super) processor: Arc<PoseObserver>,
    /// Poses in the schedule.
    pub(super) of: usize,
    pub(super) prior_note: Option<String>,
    pub(super) recording: Option<PathBuf>,
}

/// The calibration's end: the solve, the verdict, the motor's steadiness.
pub(super) fn solve_visited(
    mut visited: Visited,
    plan: &Plan,
    events: &UnboundedSender<Event>,
) -> SessionOutcome {
    let (observations, failed) = VisitedPose::fits(&visited.poses);
    let first = ResultJson::from_poses(
        &observations,
        &failed,
        visited.of,
        &plan.calibration,
        plan.tilt_deg,
    );
    // A pattern the fit's band cut: the kept frames fitted again about it,
    // as `replay` fits a recording's. Without kept frames there is nothing
    // to fit again: the first fit's residuals judged as if the pattern had
    // been taken out of them made a "pattern" of twice its size.
    let again = if visited.kept.is_empty() {
        Ok(None)
    } else {
        first.fit_about_the_pattern(|taken_out| {
            let observer = (*visited.processor)
                .clone()
                .with_depth_correction(taken_out);
            let mut poses = visited.poses.clone();
            let refits: Vec<(usize, Result<Observation, String>)> = visited
                .kept
                .par_iter()
                .map(|(at, body, kept)| {
                    let fit = match kept.frames() {
                        Some(frames) => {
                            let frames: Vec<&[u16]> = frames.iter().map(Vec::as_slice).collect();
                            observer
                                .observe(
                                    poses[*at].index,
                                    body,
                                    &frames,
                                    &mut FitBuffers::default(),
                                )
                                .map_err(|e| format!("no ground found: {e}"))
                        }
                        None => Err("its frames could not be restored for the second fit".into()),
                    };
                    (*at, fit)
                })
                .collect();
            for (at, fit) in refits {
                poses[at].fit = fit;
            }
            let (observations, failed) = VisitedPose::fits(&poses);
            let result = ResultJson::from_poses_taken_out(
                &observations,
                &failed,
                visited.of,
                &plan.calibration,
                plan.tilt_deg,
                Some(taken_out),
            );
            Ok::<_, std::convert::Infallible>((result, poses))
        })
    };
    let mut result = first.result;
    if let Ok(Some((second, poses))) = again {
        (result, visited.poses) = (second, poses);
    } else if visited.kept.is_empty() && first.fit_again_about.is_some() {
        result.notes.push(format!(
            "the depth pattern reaches beyond the ground fit's band, but this session kept no frames to fit again about it (more than {MOST_KEPT_FRAMES} frames): `groundcal replay` of its recording fits them again"
        ));
    }
    if let Some(note) = visited.prior_note {
        result.notes.insert(0, note);
    }
    result.predicted_sigma = predicted_sigma(plan);
    result.robot = Some(crate::formats::output::RobotJson {
        name: plan.robot_name.clone(),
        firmware: Some(visited.firmware.clone()),
    });
    crate::solving::verify::judge_motor(&mut result, &visited.poses, plan.tilt_deg, &plan.verify);
    send(
        events,
        Event::Finished {
            accepted: result.accepted(),
        },
    );
    SessionOutcome {
        result,
        recording: visited.recording,
    }
}

/// A check's end: the poses against the calibration.
pub(super) fn verify_visited(
    visited: Visited,
    mount: &ActiveMount,
    plan: &Plan,
    events: &UnboundedSender<Event>,
) -> Result<VerifyOutcome, SessionError> {
    let report =
        crate::solving::verify::compare(mount, &visited.poses, &plan.verify).map_err(|e| {
            SessionError::Sensor {
                kind: ErrorKind::Other,
                message: e.to_string(),
            }
        })?;
    send(
        events,
        Event::Verified {
            consistent: !report.drifted(),
        },
    );
    Ok(VerifyOutcome {
        report,
        poses: visited.poses,
        recording: visited.recording,
    })
}

/// The σ `groundcal plan` predicts for the plan's schedule, with the depth
/// scale's when it will be estimated (None without a nominal mount, or for a
/// schedule the prediction cannot solve).
pub(super) fn predicted_sigma(plan: &Plan) -> Option<crate::formats::output::SigmaJson> {
    let nominal = plan.nominal_mount?.pose().to_params();
    let poses: Vec<_> = plan.schedule.poses.iter().map(|p| p.to_params()).collect();
    let prediction = crate::calib::plan::predict_schedule_with(
        &poses,
        &nominal,
        &plan.noise,
        plan.calibration.solve.depth_scale,
    )
    .ok()?;
    if !prediction.observability.problems.is_empty() {
        return None;
    }
    let mut sigma = crate::formats::output::SigmaJson::from_radians_metres(&prediction.sigma());
    sigma.depth_scale = prediction.depth_scale.sigma;
    Some(sigma)
}
