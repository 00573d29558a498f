//! What the camera sees, small enough for a phone: one depth frame as a
//! coarse grid, with the cells that the ground fit took for the ground. A
//! person, a box, a covered lens or a wrong tilt is then seen on the page
//! before the robot moves.
//!
//! Each cell shows its centre pixel, as read: no averaging that would hide a
//! hole or smear an edge. A cell is "ground" when that reading lies in the
//! fit's own rejection band ([`GroundFit::holds`]), so the colours are the
//! fit's choice, not a second opinion.

use nalgebra::Vector3;
use serde::Serialize;

use crate::plane::GroundFit;
use crate::sensor::DepthCamera;

/// Pixels along each side of a cell: a 640 × 480 frame becomes 80 × 60.
pub const CELL_PIXELS: usize = 8;

/// A coarse picture of one depth frame and the ground found in it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GroundView {
    /// Cells across and down.
    pub width: usize,
    pub height: usize,
    /// Depth of each cell's reading in centimetres, row by row from the top
    /// left as the camera sees it; 0 where there is no reading.
    pub depth_cm: Vec<u16>,
    /// Per cell, 1 where the reading lies on the ground the fit found, else 0.
    pub ground: Vec<u8>,
    /// Why no ground was found, when none was (then no cell is 1).
    pub no_ground: Option<String>,
}

impl GroundView {
    /// The picture of `frame` (raw values of `camera`'s encoding), coloured
    /// by `fit` when a ground was found, or with the reason it was not.
    pub fn of(frame: &[u16], camera: &DepthCamera, fit: Result<&GroundFit, &str>) -> Self {
        let (width, height) = cells(frame, camera);
        let mut depth_cm = Vec::with_capacity(width * height);
        let mut ground = Vec::with_capacity(width * height);
        for point in cell_readings(frame, camera) {
            let cm = point.map_or(0.0, |p| (p.x * 100.0).round().clamp(1.0, 65535.0));
            depth_cm.push(cm as u16);
            let on_ground = match (point, fit) {
                (Some(p), Ok(fit)) => fit.holds(&p),
                _ => false,
            };
            ground.push(u8::from(on_ground));
        }
        GroundView {
            width,
            height,
            depth_cm,
            ground,
            no_ground: fit.err().map(str::to_string),
        }
    }

    /// How many cells lie on the ground.
    pub fn ground_cells(&self) -> usize {
        self.ground.iter().filter(|g| **g == 1).count()
    }

    /// How many cells have a reading.
    pub fn cells_with_depth(&self) -> usize {
        self.depth_cm.iter().filter(|d| **d > 0).count()
    }
}

/// Cells across and down in `frame`.
fn cells(frame: &[u16], camera: &DepthCamera) -> (usize, usize) {
    let image_width = camera.intrinsics().width;
    let rows = (frame.len() / image_width.max(1)).min(camera.intrinsics().height);
    (image_width / CELL_PIXELS, rows / CELL_PIXELS)
}

/// Each cell's centre reading, row by row, in the sensor frame (metres).
fn cell_readings<'a>(
    frame: &'a [u16],
    camera: &'a DepthCamera,
) -> impl Iterator<Item = Option<Vector3<f64>>> + 'a {
    let image_width = camera.intrinsics().width;
    let (width, height) = cells(frame, camera);
    (0..height).flat_map(move |row| {
        let v = row * CELL_PIXELS + CELL_PIXELS / 2;
        (0..width).map(move |column| {
            let u = column * CELL_PIXELS + CELL_PIXELS / 2;
            camera.point_at(u, v, frame[v * image_width + u])
        })
    })
}

/// The readings of the picture's ground cells as points of the sensor frame
/// (metres): the ground the fit found, one reading per cell, for a 3D view.
pub fn ground_points(frame: &[u16], camera: &DepthCamera, fit: &GroundFit) -> Vec<Vector3<f64>> {
    cell_readings(frame, camera)
        .flatten()
        .filter(|p| fit.holds(p))
        .collect()
}
