//! A pose's frames and accelerometer readings from the sensor, and their
//! record in the recording.

use super::*;

/// Writes a pose's frames and then its line to the recording on a blocking
/// worker (files and fsync: slow on an SD card, and the session's runtime
/// also drives the UDP link and the watchdog heartbeat); returns the writer.
pub(super) async fn record_pose(
    mut writer: RecordingWriter,
    frames: &[DepthFrame],
    tilt_states: &[TiltState],
    mut record: PoseRecord,
) -> Result<RecordingWriter, SessionError> {
    // Stamped as fakenect-record stamps them, with the last frame's
    // timestamp; a tenth of a millisecond apart, after that frame.
    let (last_time, last_timestamp) = frames.last().map_or((0.0, 0), |f| (f.time_s, f.timestamp));
    let readings: Vec<(f64, RawTiltState)> = tilt_states
        .iter()
        .enumerate()
        .map(|(k, s)| {
            (
                last_time + (k + 1) as f64 * 1e-4,
                RawTiltState::from_state(s),
            )
        })
        .collect();
    let images: Vec<(f64, u32, DepthImage)> = frames
        .iter()
        .map(|f| {
            let image = DepthImage {
                width: f.width,
                height: f.height,
                pixels: f.raw.clone(),
            };
            (f.time_s, f.timestamp, image)
        })
        .collect();
    writing(move || {
        record.depth_frames = images
            .iter()
            .map(|(time_s, timestamp, image)| writer.write_depth_frame(*time_s, *timestamp, image))
            .collect::<Result<Vec<String>, WriteError>>()?;
        record.accelerometer = readings
            .iter()
            .map(|(time_s, state)| writer.write_tilt_state(*time_s, last_timestamp, state))
            .collect::<Result<Vec<String>, WriteError>>()?;
        writer.write_pose(&record)?;
        Ok(writer)
    })
    .await
}

/// `write` (the recording's files) on tokio's blocking pool, awaited: files
/// and fsync are slow on an SD card, and a busy disk must not hold up the
/// session's thread (its stall watch, the UDP link, an Abort).
pub(super) async fn writing<T: Send + 'static>(
    write: impl FnOnce() -> Result<T, WriteError> + Send + 'static,
) -> Result<T, SessionError> {
    match tokio::task::spawn_blocking(write).await {
        Ok(written) => Ok(written?),
        Err(e) => Err(SessionError::Recording(format!("the writer failed: {e}"))),
    }
}

/// A pose's frames. A frame whose size is not the sensor's is corrupt and
/// skipped; more than [`MAX_CORRUPT_FRAMES`] of them at one pose fail the
/// session, as a stalled stream does.
pub(super) async fn capture<S: DepthSensor>(
    sensor: &mut S,
    plan: &Plan,
    index: u16,
    frame_count: usize,
    info: &SensorInfo,
) -> Result<Vec<DepthFrame>, SessionError> {
    let (width, height) = (info.intrinsics.width, info.intrinsics.height);
    let mut frames = Vec::with_capacity(frame_count);
    let mut corrupt = 0;
    while frames.len() < frame_count {
        let frame = bounded(
            plan,
            &format!("pose {index}: waiting for a depth frame"),
            sensor.next_frame(),
        )
        .await?;
        if frame.width == width && frame.height == height && frame.raw.len() == width * height {
            frames.push(frame);
            continue;
        }
        corrupt += 1;
        let what = format!(
            "a corrupt depth frame at pose {index}: {}×{} with {} values, where the sensor gives {width}×{height}",
            frame.width,
            frame.height,
            frame.raw.len()
        );
        if corrupt > MAX_CORRUPT_FRAMES {
            return Err(SessionError::Sensor {
                kind: ErrorKind::Protocol,
                message: format!("{corrupt} corrupt frames at pose {index}; the last was {what}"),
            });
        }
        tracing::warn!("{what}; skipped");
    }
    Ok(frames)
}

/// A pose's accelerometer readings, after its frames. A sensor that has
/// none (a recording made without) gives none; one that stops answering
/// fails the session, as a stalled stream does.
pub(super) async fn read_accelerometer<S: DepthSensor>(
    sensor: &mut S,
    plan: &Plan,
    index: u16,
) -> Result<Vec<TiltState>, SessionError> {
    let mut states = Vec::with_capacity(plan.accelerometer_readings);
    for _ in 0..plan.accelerometer_readings {
        match tokio::time::timeout(plan.sensor_timeout, sensor.tilt_state()).await {
            Ok(Ok(state)) => states.push(state),
            Ok(Err(e)) => {
                tracing::debug!("pose {index}: no accelerometer reading: {e}");
                break;
            }
            Err(_) => {
                return Err(SessionError::Sensor {
                    kind: ErrorKind::Timeout,
                    message: format!(
                        "pose {index}: the accelerometer: no answer from the depth sensor in {} s",
                        plan.sensor_timeout.as_secs_f64()
                    ),
                })
            }
        }
    }
    Ok(states)
}

/// Corrupt frames skipped at one pose before the session fails.
pub(super) const MAX_CORRUPT_FRAMES: usize = 3;
