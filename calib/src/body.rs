//! The body pose from the feet (paper section 4.2, conventions.md).
//!
//! The feet stay planted while the body moves. At the home stance the feet,
//! reported in the body frame R by forward kinematics, fix the ground frame G.
//! At every pose the feet are reported again, and `ground_from_robot` is the
//! rigid transform that best maps them back onto their ground coordinates: a
//! least-squares fit over all the feet (the paper uses the hexapod's feet 1,
//! 3 and 5 only).
//! The commanded pose is never trusted: the real one differs from it by the
//! robot's manufacturing and installation errors.
//!
//! Any legged robot: three planted feet fix the body exactly, with nothing to
//! spare; from four on (a quadruped), one foot that moved is found by
//! leaving each out in turn, and from five on (the hexapod's six) a second.

use nalgebra::{Matrix3, Rotation3, SymmetricEigen, Translation3, Vector3};

use super::geometry::Transform;

/// The fewest planted feet that fix a body: three points not on a line.
pub const MIN_FEET: usize = 3;

/// The fewest feet among which one that moved can be found: each left out,
/// the others (at least three) still fix the body.
pub const MIN_FEET_TO_FIND_A_SLIP: usize = MIN_FEET + 1;

/// The feet, foot 1 first, in metres.
pub type Feet = Vec<Vector3<f64>>;

/// Why feet do not give a pose.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BodyError {
    #[error("foot {foot} has a coordinate that is not a finite number")]
    NotFinite { foot: usize },
    #[error("the feet are (nearly) collinear, so they do not fix a ground plane")]
    Degenerate,
    #[error("{found} feet cannot fix a body: at least {MIN_FEET} are needed")]
    TooFewFeet { found: usize },
    #[error("{found} feet reported where the home stance had {planted}")]
    FeetChanged { found: usize, planted: usize },
}

/// The ground frame fixed by the home stance.
#[derive(Debug, Clone, PartialEq)]
pub struct GroundFrame {
    /// The body pose at the home stance.
    pub ground_from_robot_home: Transform,
    /// The feet in the ground frame (`y ≈ 0`), foot 1 first.
    pub feet_ground: Feet,
}

/// The body pose at one observation, with how well the feet agree with it.
#[derive(Debug, Clone, PartialEq)]
pub struct BodyPose {
    pub ground_from_robot: Transform,
    /// Distance from each reported foot, mapped to the ground, to where it was
    /// planted, metres.
    pub foot_residuals: Vec<f64>,
    /// The foot that moved since it was planted, if one did (1-based), with
    /// how far it is from where the others put it, metres. The pose is then
    /// the others': the remaining planted feet fix the body. Never found
    /// among fewer than [`MIN_FEET_TO_FIND_A_SLIP`] feet.
    pub slipped_foot: Option<(usize, f64)>,
    /// Why the feet do not fix the pose, if they do not: a second foot that
    /// moved, with how far, metres (1-based).
    pub second_slipped_foot: Option<(usize, f64)>,
    /// The farthest any foot lies from where the others put it, metres,
    /// whether or not it counts as a slip: the feet's own scatter, pose by
    /// pose. None among fewer than [`MIN_FEET_TO_FIND_A_SLIP`] feet.
    pub worst_miss: Option<f64>,
}

fn check_finite(feet: &[Vector3<f64>]) -> Result<(), BodyError> {
    for (i, f) in feet.iter().enumerate() {
        if !f.iter().all(|v| v.is_finite()) {
            return Err(BodyError::NotFinite { foot: i + 1 });
        }
    }
    Ok(())
}

fn centroid(points: &[Vector3<f64>]) -> Vector3<f64> {
    points.iter().sum::<Vector3<f64>>() / points.len() as f64
}

impl GroundFrame {
    /// The ground frame of conventions.md: the least-squares plane through the
    /// home feet, Y up (towards the body), origin below the body origin, X the
    /// projection of the body's X.
    pub fn from_home_feet(feet_robot: &[Vector3<f64>]) -> Result<Self, BodyError> {
        if feet_robot.len() < MIN_FEET {
            return Err(BodyError::TooFewFeet {
                found: feet_robot.len(),
            });
        }
        check_finite(feet_robot)?;
        let c = centroid(feet_robot);
        let scatter: Matrix3<f64> = feet_robot
            .iter()
            .map(|f| (f - c) * (f - c).transpose())
            .sum();
        let eigen = SymmetricEigen::new(scatter);
        let mut order = [0usize, 1, 2];
        order.sort_by(|&a, &b| eigen.eigenvalues[a].total_cmp(&eigen.eigenvalues[b]));
        // The feet must span a plane: the middle eigenvalue well above zero.
        if eigen.eigenvalues[order[1]] < 1e-8 {
            return Err(BodyError::Degenerate);
        }
        let mut up: Vector3<f64> = eigen.eigenvectors.column(order[0]).into_owned();
        // Up points from the feet towards the body origin.
        if up.dot(&(-c)) < 0.0 {
            up = -up;
        }
        let forward = Vector3::x() - up * up.x;
        let forward = if forward.norm() > 1e-6 {
            forward.normalize()
        } else {
            // The body's X is vertical: fall back on its Z for the heading.
            (Vector3::z() - up * up.z).normalize().cross(&up)
        };
        let right = forward.cross(&up);
        // Rows of ground_R_robot are the ground axes in body coordinates.
        let rotation =
            Matrix3::from_rows(&[forward.transpose(), up.transpose(), right.transpose()]);
        // The point of the plane below R's origin.
        let origin_robot = up * up.dot(&c);
        let translation = -(rotation * origin_robot);
        let ground_from_robot_home = Transform::from_parts(
            Translation3::from(translation),
            Rotation3::from_matrix_unchecked(rotation),
        );
        let feet_ground = feet_robot
            .iter()
            .map(|f| (ground_from_robot_home * nalgebra::Point3::from(*f)).coords)
            .collect();
        Ok(Self {
            ground_from_robot_home,
            feet_ground,
        })
    }

    /// The body pose from the feet reported at one pose.
    ///
    /// A foot has slipped when, fitted without it, it lies more than
    /// `slip_threshold` (metres) from where the other feet put it. The worst
    /// such foot is left out and the pose is the others'. A second foot that
    /// disagrees with the remaining ones is reported too: the feet then do
    /// not fix the pose. Among three feet neither can be found: each is
    /// needed to fix the body.
    pub fn body_pose(
        &self,
        feet_robot: &[Vector3<f64>],
        slip_threshold: f64,
    ) -> Result<BodyPose, BodyError> {
        if feet_robot.len() != self.feet_ground.len() {
            return Err(BodyError::FeetChanged {
                found: feet_robot.len(),
                planted: self.feet_ground.len(),
            });
        }
        check_finite(feet_robot)?;
        let all: Vec<usize> = (0..feet_robot.len()).collect();
        let worst = self.worst_miss(feet_robot, &all)?;
        let slipped_foot = worst.filter(|(_, miss)| *miss > slip_threshold);
        let (kept, second_slipped_foot) = match slipped_foot {
            None => (all, None),
            Some((foot, _)) => {
                let others: Vec<usize> = all.into_iter().filter(|&i| i != foot).collect();
                let second = self
                    .worst_miss(feet_robot, &others)?
                    .filter(|(_, miss)| *miss > slip_threshold)
                    .map(|(f, miss)| (f + 1, miss));
                (others, second)
            }
        };
        let ground_from_robot = rigid_fit(feet_robot, &self.feet_ground, &kept)?;
        let foot_residuals = feet_robot
            .iter()
            .zip(&self.feet_ground)
            .map(|(foot, ground)| {
                ((ground_from_robot * nalgebra::Point3::from(*foot)).coords - ground).norm()
            })
            .collect();
        Ok(BodyPose {
            ground_from_robot,
            foot_residuals,
            slipped_foot: slipped_foot.map(|(f, miss)| (f + 1, miss)),
            second_slipped_foot,
            worst_miss: worst.map(|(_, miss)| miss),
        })
    }

    /// Among `feet`, the foot (0-based) farthest from where the others put
    /// it, with that distance; none when the others are too few to fix the
    /// body without it.
    fn worst_miss(
        &self,
        feet_robot: &[Vector3<f64>],
        feet: &[usize],
    ) -> Result<Option<(usize, f64)>, BodyError> {
        if feet.len() < MIN_FEET_TO_FIND_A_SLIP {
            return Ok(None);
        }
        let mut worst: Option<(usize, f64)> = None;
        for &out in feet {
            let others: Vec<usize> = feet.iter().copied().filter(|&i| i != out).collect();
            let fit = rigid_fit(feet_robot, &self.feet_ground, &others)?;
            let miss = ((fit * nalgebra::Point3::from(feet_robot[out])).coords
                - self.feet_ground[out])
                .norm();
            if worst.is_none_or(|(_, w)| miss > w) {
                worst = Some((out, miss));
            }
        }
        Ok(worst)
    }

    /// Plants a foot anew where it is now (1-based `foot`), seen from the body
    /// pose the other feet give: a foot that slipped and stays where it
    /// slipped agrees again at the following poses.
    pub fn replant(
        &mut self,
        foot: usize,
        feet_robot: &[Vector3<f64>],
        ground_from_robot: &Transform,
    ) {
        let index = foot.checked_sub(1);
        if let (Some(anchor), Some(now)) = (
            index.and_then(|i| self.feet_ground.get_mut(i)),
            index.and_then(|i| feet_robot.get(i)),
        ) {
            *anchor = (ground_from_robot * nalgebra::Point3::from(*now)).coords;
        }
    }
}

/// Least-squares rigid transform `to_from_from` mapping `from[i]` onto `to[i]` for
/// the chosen indices (Kabsch / Umeyama without scale).
fn rigid_fit(
    from: &[Vector3<f64>],
    to: &[Vector3<f64>],
    indices: &[usize],
) -> Result<Transform, BodyError> {
    let a: Vec<Vector3<f64>> = indices.iter().map(|&i| from[i]).collect();
    let b: Vec<Vector3<f64>> = indices.iter().map(|&i| to[i]).collect();
    let ca = centroid(&a);
    let cb = centroid(&b);
    let h: Matrix3<f64> = a
        .iter()
        .zip(&b)
        .map(|(p, q)| (q - cb) * (p - ca).transpose())
        .sum();
    let svd = h.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(BodyError::Degenerate);
    };
    let mut sorted = svd.singular_values.as_slice().to_vec();
    sorted.sort_by(f64::total_cmp);
    if sorted[1] < 1e-10 {
        return Err(BodyError::Degenerate);
    }
    let sign = (u * v_t).determinant().signum();
    let rotation = u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, sign)) * v_t;
    let translation = cb - rotation * ca;
    Ok(Transform::from_parts(
        Translation3::from(translation),
        Rotation3::from_matrix_unchecked(rotation),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::PoseParams;
    use approx::assert_abs_diff_eq;

    /// The sample's home stance: a hexagon 600 mm below the body.
    fn home_feet() -> Feet {
        vec![
            Vector3::new(0.693, -0.600, 0.400),
            Vector3::new(0.000, -0.600, 0.800),
            Vector3::new(-0.693, -0.600, 0.400),
            Vector3::new(-0.693, -0.600, -0.400),
            Vector3::new(0.000, -0.600, -0.800),
            Vector3::new(0.693, -0.600, -0.400),
        ]
    }

    #[test]
    fn level_home_stance_gives_a_pure_height() {
        let frame = GroundFrame::from_home_feet(&home_feet()).unwrap();
        let t = frame.ground_from_robot_home;
        assert_abs_diff_eq!(*t.rotation.matrix(), Matrix3::identity(), epsilon = 1e-12);
        assert_abs_diff_eq!(
            t.translation.vector,
            Vector3::new(0.0, 0.6, 0.0),
            epsilon = 1e-12
        );
        assert!(frame.feet_ground.iter().all(|f| f.y.abs() < 1e-12));
    }

    #[test]
    fn a_tilted_home_stance_is_levelled() {
        let tilt = PoseParams::new(0.0, 0.05, -0.03, Vector3::new(0.0, 0.0, 0.0)).to_transform();
        let feet: Feet = home_feet()
            .iter()
            .map(|f| (tilt * nalgebra::Point3::from(*f)).coords)
            .collect();
        let frame = GroundFrame::from_home_feet(&feet).unwrap();
        assert!(frame.feet_ground.iter().all(|f| f.y.abs() < 1e-12));
        // The body origin is 600 mm above the ground.
        assert_abs_diff_eq!(
            frame.ground_from_robot_home.translation.vector.y,
            0.6,
            epsilon = 1e-9
        );
    }

    #[test]
    fn recovers_the_real_body_pose_from_the_feet() {
        let frame = GroundFrame::from_home_feet(&home_feet()).unwrap();
        let truth =
            PoseParams::new(0.01, 0.2, 0.3, Vector3::new(0.002, 0.65, -0.001)).to_transform();
        let feet = frame
            .feet_ground
            .iter()
            .map(|g| (truth.inverse() * nalgebra::Point3::from(*g)).coords)
            .collect::<Feet>();
        let pose = frame.body_pose(&feet, 0.005).unwrap();
        assert_abs_diff_eq!(
            pose.ground_from_robot.to_homogeneous(),
            truth.to_homogeneous(),
            epsilon = 1e-12
        );
        assert!(pose.slipped_foot.is_none());
        assert!(pose.foot_residuals.iter().all(|r| *r < 1e-12));
    }

    #[test]
    fn a_slipped_foot_is_named_and_left_out_of_the_pose() {
        let frame = GroundFrame::from_home_feet(&home_feet()).unwrap();
        let truth = PoseParams::new(0.0, -0.1, 0.2, Vector3::new(0.0, 0.7, 0.0)).to_transform();
        let mut feet = frame
            .feet_ground
            .iter()
            .map(|g| (truth.inverse() * nalgebra::Point3::from(*g)).coords)
            .collect::<Feet>();
        feet[2] += Vector3::new(0.03, 0.0, 0.01);
        let pose = frame.body_pose(&feet, 0.005).unwrap();
        let (foot, miss) = pose.slipped_foot.unwrap();
        assert_eq!(foot, 3);
        assert!((miss - 0.0316).abs() < 0.002, "{miss}");
        assert_eq!(pose.second_slipped_foot, None);
        // The other five give the body pose exactly.
        assert_abs_diff_eq!(
            pose.ground_from_robot.to_homogeneous(),
            truth.to_homogeneous(),
            epsilon = 1e-12
        );
    }

    #[test]
    fn a_foot_that_stays_where_it_slipped_is_replanted() {
        let mut frame = GroundFrame::from_home_feet(&home_feet()).unwrap();
        let sunk = Vector3::new(0.0, -0.015, 0.0);
        let feet_at = |truth: &Transform, frame: &GroundFrame| {
            let mut ground = frame.feet_ground.clone();
            ground[4] = home_feet()[4] + Vector3::new(0.0, 0.6, 0.0) + sunk;
            ground
                .iter()
                .map(|g| (truth.inverse() * nalgebra::Point3::from(*g)).coords)
                .collect::<Feet>()
        };
        let first = PoseParams::new(0.0, 0.1, 0.0, Vector3::new(0.0, 0.65, 0.0)).to_transform();
        let feet = feet_at(&first, &frame);
        let pose = frame.body_pose(&feet, 0.010).unwrap();
        assert_eq!(pose.slipped_foot.map(|s| s.0), Some(5));
        frame.replant(5, &feet, &pose.ground_from_robot);
        // At the next pose the sunk foot agrees again, and all six count.
        let next = PoseParams::new(0.0, -0.1, 0.1, Vector3::new(0.0, 0.62, 0.0)).to_transform();
        let pose = frame.body_pose(&feet_at(&next, &frame), 0.010).unwrap();
        assert_eq!(pose.slipped_foot, None);
        assert_abs_diff_eq!(
            pose.ground_from_robot.to_homogeneous(),
            next.to_homogeneous(),
            epsilon = 1e-9
        );
    }

    #[test]
    fn two_slipped_feet_are_both_named() {
        let frame = GroundFrame::from_home_feet(&home_feet()).unwrap();
        let truth = PoseParams::new(0.0, 0.0, 0.1, Vector3::new(0.0, 0.6, 0.0)).to_transform();
        let mut feet = frame
            .feet_ground
            .iter()
            .map(|g| (truth.inverse() * nalgebra::Point3::from(*g)).coords)
            .collect::<Feet>();
        feet[0] += Vector3::new(0.0, 0.03, 0.0);
        feet[3] += Vector3::new(0.02, 0.0, 0.0);
        let pose = frame.body_pose(&feet, 0.010).unwrap();
        assert!(pose.slipped_foot.is_some());
        assert!(pose.second_slipped_foot.is_some(), "{pose:?}");
    }

    #[test]
    fn collinear_or_broken_feet_are_errors() {
        let line: Feet = (0..6).map(|i| Vector3::new(i as f64, -0.6, 0.0)).collect();
        assert_eq!(
            GroundFrame::from_home_feet(&line),
            Err(BodyError::Degenerate)
        );
        let mut feet = home_feet();
        feet[4].y = f64::NAN;
        assert_eq!(
            GroundFrame::from_home_feet(&feet),
            Err(BodyError::NotFinite { foot: 5 })
        );
        assert_eq!(
            GroundFrame::from_home_feet(&home_feet()[..2]),
            Err(BodyError::TooFewFeet { found: 2 })
        );
        let frame = GroundFrame::from_home_feet(&home_feet()).unwrap();
        assert_eq!(
            frame.body_pose(&home_feet()[..5], 0.01),
            Err(BodyError::FeetChanged {
                found: 5,
                planted: 6
            })
        );
    }

    /// A quadruped's stance: four feet in a rectangle 350 mm below the body.
    fn quadruped_feet() -> Feet {
        vec![
            Vector3::new(0.25, -0.35, -0.15),
            Vector3::new(0.25, -0.35, 0.15),
            Vector3::new(-0.25, -0.35, -0.15),
            Vector3::new(-0.25, -0.35, 0.15),
        ]
    }

    fn feet_seen_from(frame: &GroundFrame, truth: &Transform) -> Feet {
        frame
            .feet_ground
            .iter()
            .map(|g| (truth.inverse() * nalgebra::Point3::from(*g)).coords)
            .collect()
    }

    #[test]
    fn four_feet_give_the_pose_and_name_a_slipped_one() {
        let frame = GroundFrame::from_home_feet(&quadruped_feet()).unwrap();
        let truth =
            PoseParams::new(0.02, -0.08, 0.12, Vector3::new(0.01, 0.37, -0.02)).to_transform();
        let feet = feet_seen_from(&frame, &truth);
        let pose = frame.body_pose(&feet, 0.005).unwrap();
        assert_abs_diff_eq!(
            pose.ground_from_robot.to_homogeneous(),
            truth.to_homogeneous(),
            epsilon = 1e-12
        );
        assert_eq!(pose.slipped_foot, None);
        assert_eq!(pose.foot_residuals.len(), 4);
        // Foot 2 slides 20 mm: named, and the other three fix the body.
        let mut slipped = feet.clone();
        slipped[1] += Vector3::new(0.02, 0.0, 0.0);
        let pose = frame.body_pose(&slipped, 0.005).unwrap();
        let (foot, miss) = pose.slipped_foot.unwrap();
        assert_eq!(foot, 2);
        assert!((miss - 0.02).abs() < 1e-9, "{miss}");
        assert_eq!(
            pose.second_slipped_foot, None,
            "three feet cannot tell a second"
        );
        assert_abs_diff_eq!(
            pose.ground_from_robot.to_homogeneous(),
            truth.to_homogeneous(),
            epsilon = 1e-12
        );
    }

    #[test]
    fn three_feet_fix_the_pose_but_cannot_find_a_slip() {
        let three = &quadruped_feet()[..3];
        let frame = GroundFrame::from_home_feet(three).unwrap();
        let truth = PoseParams::new(0.0, 0.05, -0.04, Vector3::new(0.0, 0.36, 0.0)).to_transform();
        let mut feet = feet_seen_from(&frame, &truth);
        let pose = frame.body_pose(&feet, 0.005).unwrap();
        assert_abs_diff_eq!(
            pose.ground_from_robot.to_homogeneous(),
            truth.to_homogeneous(),
            epsilon = 1e-12
        );
        feet[0] += Vector3::new(0.03, 0.0, 0.0);
        let pose = frame.body_pose(&feet, 0.005).unwrap();
        assert_eq!(pose.slipped_foot, None);
        assert!(pose.foot_residuals.iter().any(|r| *r > 0.005));
    }
}
