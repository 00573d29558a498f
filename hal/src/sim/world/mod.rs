//! The simulated world the simulated Kinect looks at, in the ground frame G
//! (Y up, the ground at `y = 0`; conventions.md).
//!
//! The calibration assumes only that the robot stands on a ground it can see.
//! The simulator must therefore also show it what makes that hard on real
//! floors: boxes whose tops are planes parallel to the ground, walls that are
//! large planes of their own, and ground that is not quite flat. A [`World`] is
//! a ground (flat or a smooth [`HeightField`]) with [`BoxObstacle`]s standing on
//! it and finite vertical [`Wall`]s; [`World::cast`] finds where a ray meets it,
//! exactly for the planes and boxes and to well below a micrometre for the
//! height field.
//!
//! Scenarios are constructors: [`World::flat`], [`World::boxes_and_wall`] and
//! [`World::uneven`]. The seeded ones are deterministic: the same seed gives
//! the same world on every machine. The height field and the ray's hit on
//! it are in [`height_field`].

use nalgebra::{Point3, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

mod height_field;
pub use height_field::*;

/// Hits closer than this to the ray's origin (in units of the ray parameter)
/// are ignored, so that a ray leaving a surface does not hit that surface.
const T_MIN: f64 = 1e-9;

/// Where a ray meets the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// The ray parameter: the point is `origin + t·direction` (the distance in
    /// metres when the direction is a unit vector).
    pub t: f64,
    /// The surface's unit normal at the hit, facing the ray's origin.
    pub normal: Vector3<f64>,
    /// What was hit.
    pub surface: Surface,
}

/// The part of the world a ray hit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Surface {
    Ground,
    /// The box of that index in [`World::boxes`].
    Box(usize),
    /// The wall of that index in [`World::walls`].
    Wall(usize),
}

/// What a caller of [`World::cast_with`] knows about a ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayHints {
    /// The obstacles the ray may meet: bit `i` for obstacle `i` of
    /// [`World::obstacle_corners`] (boxes, then walls); obstacles from the
    /// 65th on are always asked. A sensor clears the bits of obstacles whose
    /// image does not hold the pixel.
    pub candidates: u64,
    /// The ground's height near where the ray lands (a neighbouring pixel's
    /// hit): Newton starts there on uneven ground.
    pub ground_height: Option<f64>,
}

impl Default for RayHints {
    /// Nothing known: every obstacle is asked.
    fn default() -> Self {
        Self {
            candidates: u64::MAX,
            ground_height: None,
        }
    }
}

/// Whether obstacle `i` is among `candidates` (bit `i`; always from 64 on).
fn is_candidate(candidates: u64, i: usize) -> bool {
    i >= 64 || candidates & (1 << i) != 0
}

/// The ground the robot stands on.
#[derive(Debug, Clone, PartialEq)]
pub enum Ground {
    /// The plane `y = 0`.
    Flat,
    /// A smooth surface near `y = 0`.
    HeightField(HeightField),
}

/// A box standing on the ground: a vertical prism on a rectangle, rotated
/// about the vertical by `yaw`. Its top is a plane parallel to the ground, the
/// kind of plane a careless ground fit takes for the ground.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxObstacle {
    /// Centre of the footprint, ground X and Z, metres.
    pub centre_x: f64,
    pub centre_z: f64,
    /// Half the footprint along the box's own x and z, metres.
    pub half_x: f64,
    pub half_z: f64,
    /// Height of the top above `y = 0`, metres.
    pub height: f64,
    /// Rotation about ground Y (as `Ry` of conventions.md), radians.
    pub yaw: f64,
}

impl BoxObstacle {
    /// Ray against box by the slab method, in the box's own frame.
    fn cast(&self, origin: &Point3<f64>, direction: &Vector3<f64>) -> Option<(f64, Vector3<f64>)> {
        let (s, c) = self.yaw.sin_cos();
        // box_from_ground = Ry(yaw)ᵀ about the footprint's centre.
        let to_box = |v: Vector3<f64>| Vector3::new(c * v.x - s * v.z, v.y, s * v.x + c * v.z);
        let o = to_box(Vector3::new(
            origin.x - self.centre_x,
            origin.y,
            origin.z - self.centre_z,
        ));
        let d = to_box(*direction);
        let lo = [-self.half_x, 0.0, -self.half_z];
        let hi = [self.half_x, self.height, self.half_z];
        let (mut t_near, mut t_far) = (f64::NEG_INFINITY, f64::INFINITY);
        let (mut near_axis, mut far_axis) = (0, 0);
        for axis in 0..3 {
            if d[axis].abs() < 1e-15 {
                if o[axis] < lo[axis] || o[axis] > hi[axis] {
                    return None;
                }
                continue;
            }
            let t1 = (lo[axis] - o[axis]) / d[axis];
            let t2 = (hi[axis] - o[axis]) / d[axis];
            let (a, b) = if t1 < t2 { (t1, t2) } else { (t2, t1) };
            if a > t_near {
                t_near = a;
                near_axis = axis;
            }
            if b < t_far {
                t_far = b;
                far_axis = axis;
            }
        }
        if t_near > t_far || t_far <= T_MIN {
            return None;
        }
        // From inside the box (never for a sensor that sees it) the exit face.
        let (t, axis) = if t_near > T_MIN {
            (t_near, near_axis)
        } else {
            (t_far, far_axis)
        };
        let mut local = Vector3::zeros();
        local[axis] = -d[axis].signum();
        // Back to ground: Ry(yaw).
        let normal = Vector3::new(
            c * local.x + s * local.z,
            local.y,
            -s * local.x + c * local.z,
        );
        Some((t, normal))
    }
}

/// A finite vertical wall from `y = 0` to `height`, along the segment from
/// `start` to `end` on the ground (X, Z). It has no thickness: it is seen from
/// both sides.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wall {
    /// Ground (X, Z) of one end, metres.
    pub start: Vector2<f64>,
    /// Ground (X, Z) of the other end, metres.
    pub end: Vector2<f64>,
    /// Metres.
    pub height: f64,
}

impl Wall {
    fn cast(&self, origin: &Point3<f64>, direction: &Vector3<f64>) -> Option<(f64, Vector3<f64>)> {
        let along = self.end - self.start;
        let length = along.norm();
        if length <= 0.0 {
            return None;
        }
        let u = along / length;
        let mut normal = Vector3::new(-u.y, 0.0, u.x);
        let denominator = normal.dot(direction);
        if denominator.abs() < 1e-15 {
            return None;
        }
        let to_wall = Vector3::new(self.start.x - origin.x, -origin.y, self.start.y - origin.z);
        let t = normal.dot(&to_wall) / denominator;
        if t <= T_MIN {
            return None;
        }
        let p = origin + direction * t;
        let s = (Vector2::new(p.x, p.z) - self.start).dot(&u);
        if !(0.0..=length).contains(&s) || !(0.0..=self.height).contains(&p.y) {
            return None;
        }
        if denominator > 0.0 {
            normal = -normal;
        }
        Some((t, normal))
    }
}

/// The simulated world in the ground frame G.
#[derive(Debug, Clone, PartialEq)]
pub struct World {
    pub ground: Ground,
    pub boxes: Vec<BoxObstacle>,
    pub walls: Vec<Wall>,
}

impl World {
    /// Flat ground and nothing else: the calibration's ideal.
    pub fn flat() -> Self {
        Self {
            ground: Ground::Flat,
            boxes: Vec::new(),
            walls: Vec::new(),
        }
    }

    /// Flat ground with two boxes (0.1–0.4 m high) and a wall, seeded.
    ///
    /// They are placed where the Kinect of a hexapod looks during a schedule
    /// such as octopus-52: the sensor sits about 0.5 m ahead of the body's
    /// origin, 0.9–1.1 m above the ground, pitched 10–50° down. The boxes
    /// (footprints 0.2–0.4 m) stand 1.6–2.5 m ahead of the body's origin, one
    /// on each side of the view's centre line; the wall is 2–3 m ahead of the
    /// sensor (ground X 2.5–3.5 m), 1.0–1.5 m wide and off to one side,
    /// 0.8–1.2 m high. The ground keeps most of the image: the wall hides
    /// only ground that is far, and far ground is out of range when the body
    /// pitches up.
    pub fn boxes_and_wall(seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let side = if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
        let mut boxes = Vec::new();
        for (i, lateral) in [(0, 0.2..0.5), (1, 0.3..0.6)] {
            let sign = if i == 0 { side } else { -side };
            boxes.push(BoxObstacle {
                centre_x: rng.gen_range(1.6..2.5),
                centre_z: sign * rng.gen_range(lateral),
                half_x: rng.gen_range(0.1..0.2),
                half_z: rng.gen_range(0.1..0.2),
                height: rng.gen_range(0.1..0.4),
                yaw: rng.gen_range(-0.6..0.6),
            });
        }
        let x = rng.gen_range(2.5..3.5);
        let width = rng.gen_range(1.0..1.5);
        let centre_z = -side * rng.gen_range(1.0..1.4);
        let skew = rng.gen_range(-0.3..0.3);
        let walls = vec![Wall {
            start: Vector2::new(x - skew, centre_z - width / 2.0),
            end: Vector2::new(x + skew, centre_z + width / 2.0),
            height: rng.gen_range(0.8..1.2),
        }];
        Self {
            ground: Ground::Flat,
            boxes,
            walls,
        }
    }

    /// Clutter: four boxes and a long wall across the whole view, seeded.
    ///
    /// The boxes are 0.10–0.35 m tall and 0.3–0.8 m across, 1.3–2.6 m ahead
    /// of the body's origin and up to 0.8 m to either side; the wall, 2 m
    /// high, stands 3.8 m ahead and spans 12 m, so that it meets the floor
    /// across the far end of the view. The ground is a fifth to four fifths
    /// of the valid pixels, depending on the pose.
    pub fn clutter(seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut boxes = Vec::new();
        for k in 0..4 {
            // Two on each side of the centre line, one near and one far.
            let side = if k % 2 == 0 { 1.0 } else { -1.0 };
            let (near, far) = if k < 2 { (1.3, 1.9) } else { (1.9, 2.6) };
            boxes.push(BoxObstacle {
                centre_x: rng.gen_range(near..far),
                centre_z: side * rng.gen_range(0.0..0.8),
                half_x: rng.gen_range(0.15..0.4),
                half_z: rng.gen_range(0.15..0.4),
                height: rng.gen_range(0.10..0.35),
                yaw: rng.gen_range(-0.6..0.6),
            });
        }
        Self {
            ground: Ground::Flat,
            boxes,
            walls: vec![Wall {
                start: Vector2::new(3.8, -6.0),
                end: Vector2::new(3.8, 6.0),
                height: 2.0,
            }],
        }
    }

    /// Low boxes whose tops sit near the floor, seeded: six boxes 0.05–0.10 m
    /// tall (two of them 0.05–0.06 m), 0.2–0.6 m across, 1.2–2.8 m ahead of
    /// the body's origin and up to 1 m to either side. Their tops are
    /// parallel to the ground and a few centimetres above it: the hardest
    /// case for telling the ground from what stands on it.
    pub fn low_boxes(seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let boxes = (0..6)
            .map(|k| BoxObstacle {
                centre_x: rng.gen_range(1.2..2.8),
                centre_z: rng.gen_range(-1.0..1.0),
                half_x: rng.gen_range(0.1..0.3),
                half_z: rng.gen_range(0.1..0.3),
                height: if k < 2 {
                    rng.gen_range(0.05..0.06)
                } else {
                    rng.gen_range(0.05..0.10)
                },
                yaw: rng.gen_range(-0.8..0.8),
            })
            .collect();
        Self {
            ground: Ground::Flat,
            boxes,
            walls: Vec::new(),
        }
    }

    /// A wall that meets the floor in view, seeded: 2.6–3.2 m ahead of the
    /// body's origin, turned by up to 20° from square, 12 m long and 1.5 m
    /// high; nothing else.
    pub fn wall_meeting_floor(seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let x = rng.gen_range(2.6..3.2);
        let turn: f64 = rng.gen_range(-20f64..20.0).to_radians();
        let (along_x, along_z) = (6.0 * turn.sin(), 6.0 * turn.cos());
        Self {
            ground: Ground::Flat,
            boxes: Vec::new(),
            walls: vec![Wall {
                start: Vector2::new(x - along_x, -along_z),
                end: Vector2::new(x + along_x, along_z),
                height: 1.5,
            }],
        }
    }

    /// A corridor full of people: the floor is about a tenth of the view.
    ///
    /// Two walls 2.5 m high run along the body's X, 0.95–1.05 m to either
    /// side, and five people-sized boxes (0.4–0.5 m wide, 0.25–0.35 m deep,
    /// 1.65–1.9 m tall) stand 1.3–2.1 m ahead of the body's origin in two
    /// ranks, the second covering the gaps of the first. From the sensor of
    /// a hexapod (about 0.5 m ahead of the body, 0.9–1.1 m up, pitched
    /// 25–45° down) the floor shows only in a strip at the bottom of the
    /// image and between the people's feet: the test of a ground search
    /// that must not need the floor to dominate the view.
    pub fn corridor(seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut walls = Vec::new();
        for side in [-1.0, 1.0] {
            let z = side * rng.gen_range(0.95..1.05);
            walls.push(Wall {
                start: Vector2::new(-2.0, z),
                end: Vector2::new(8.0, z),
                height: 2.5,
            });
        }
        let mut boxes = Vec::new();
        let ranks: [(f64, &[f64]); 2] = [(1.35, &[-0.55, 0.0, 0.55]), (1.9, &[-0.28, 0.28])];
        for (x, lateral) in ranks {
            for &z in lateral {
                boxes.push(BoxObstacle {
                    centre_x: x + rng.gen_range(-0.05..0.15),
                    centre_z: z + rng.gen_range(-0.04..0.04),
                    half_x: rng.gen_range(0.125..0.175),
                    half_z: rng.gen_range(0.2..0.25),
                    height: rng.gen_range(1.65..1.9),
                    yaw: rng.gen_range(-0.3..0.3),
                });
            }
        }
        Self {
            ground: Ground::Flat,
            boxes,
            walls,
        }
    }

    /// Uneven ground: a seeded [`HeightField`] within `±amplitude_m` of
    /// `y = 0` (a few millimetres to about 2 cm for real floors).
    pub fn uneven(seed: u64, amplitude_m: f64) -> Self {
        Self {
            ground: Ground::HeightField(HeightField::seeded(seed, amplitude_m)),
            boxes: Vec::new(),
            walls: Vec::new(),
        }
    }

    /// The height of the ground at `(x, z)`, ignoring boxes and walls.
    pub fn ground_height(&self, x: f64, z: f64) -> f64 {
        match &self.ground {
            Ground::Flat => 0.0,
            Ground::HeightField(field) => field.height(x, z),
        }
    }

    /// The ray parameter of the first hit of the ray `origin + t·direction`
    /// (the distance when `direction` is a unit vector), if any.
    pub fn hit(&self, origin: &Point3<f64>, direction: &Vector3<f64>) -> Option<f64> {
        self.cast(origin, direction, f64::INFINITY).map(|h| h.t)
    }

    /// Whether a box or a wall meets the ray with `t ≤ t_max`. The ground is
    /// not asked: a flat ground cannot stand between two points above it,
    /// and a height field of centimetres hides nothing from a sensor a metre
    /// above it. This is the cheap test of the emitter's shadows.
    pub fn blocked_by_obstacle(
        &self,
        origin: &Point3<f64>,
        direction: &Vector3<f64>,
        t_max: f64,
    ) -> bool {
        self.blocked_by_obstacle_among(origin, direction, t_max, u64::MAX)
    }

    /// [`World::blocked_by_obstacle`] among the obstacles whose bits are set
    /// in `candidates` (as in [`RayHints::candidates`]).
    pub fn blocked_by_obstacle_among(
        &self,
        origin: &Point3<f64>,
        direction: &Vector3<f64>,
        t_max: f64,
        candidates: u64,
    ) -> bool {
        let n = self.boxes.len();
        self.boxes
            .iter()
            .enumerate()
            .filter(|&(i, _)| is_candidate(candidates, i))
            .filter_map(|(_, b)| b.cast(origin, direction))
            .chain(
                self.walls
                    .iter()
                    .enumerate()
                    .filter(|&(i, _)| is_candidate(candidates, n + i))
                    .filter_map(|(_, w)| w.cast(origin, direction)),
            )
            .any(|(t, _)| t <= t_max)
    }

    /// Whether the world has anything but ground.
    pub fn has_obstacles(&self) -> bool {
        !(self.boxes.is_empty() && self.walls.is_empty())
    }

    /// The corners of each obstacle, boxes first, then walls: obstacle `i`
    /// lies within the convex hull of its corners. A sensor projects them to
    /// know which pixels can see an obstacle at all, and asks only those
    /// pixels' rays about it ([`RayHints::candidates`]).
    pub fn obstacle_corners(&self) -> Vec<Vec<Point3<f64>>> {
        let boxes = self.boxes.iter().map(|b| {
            let (s, c) = b.yaw.sin_cos();
            let mut corners = Vec::with_capacity(8);
            for (dx, dz) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
                let (x, z) = (dx * b.half_x, dz * b.half_z);
                // Ry(yaw) · (x, ·, z) about the footprint's centre.
                let (gx, gz) = (b.centre_x + c * x + s * z, b.centre_z - s * x + c * z);
                corners.push(Point3::new(gx, 0.0, gz));
                corners.push(Point3::new(gx, b.height, gz));
            }
            corners
        });
        let walls = self.walls.iter().map(|w| {
            vec![
                Point3::new(w.start.x, 0.0, w.start.y),
                Point3::new(w.start.x, w.height, w.start.y),
                Point3::new(w.end.x, 0.0, w.end.y),
                Point3::new(w.end.x, w.height, w.end.y),
            ]
        });
        boxes.chain(walls).collect()
    }

    /// The first hit with `t ≤ t_max`, with its normal and surface. Capping
    /// `t` lets a sensor skip what is beyond its range.
    pub fn cast(&self, origin: &Point3<f64>, direction: &Vector3<f64>, t_max: f64) -> Option<Hit> {
        self.cast_with(origin, direction, t_max, &RayHints::default())
    }

    /// [`World::cast`] with what the caller knows to save work; the hit is
    /// the same (to far below a micrometre) with any hints that are true.
    pub fn cast_with(
        &self,
        origin: &Point3<f64>,
        direction: &Vector3<f64>,
        t_max: f64,
        hints: &RayHints,
    ) -> Option<Hit> {
        let candidates = hints.candidates;
        let mut best: Option<Hit> = None;
        let mut limit = t_max;
        for (i, b) in self.boxes.iter().enumerate() {
            if !is_candidate(candidates, i) {
                continue;
            }
            if let Some((t, normal)) = b.cast(origin, direction) {
                if t <= limit {
                    limit = t;
                    best = Some(Hit {
                        t,
                        normal,
                        surface: Surface::Box(i),
                    });
                }
            }
        }
        let n = self.boxes.len();
        for (i, w) in self.walls.iter().enumerate() {
            if !is_candidate(candidates, n + i) {
                continue;
            }
            if let Some((t, normal)) = w.cast(origin, direction) {
                if t <= limit {
                    limit = t;
                    best = Some(Hit {
                        t,
                        normal,
                        surface: Surface::Wall(i),
                    });
                }
            }
        }
        // The ground last: the height field's search stops at the nearest
        // obstacle already found.
        let ground = match &self.ground {
            Ground::Flat => {
                let t = -origin.y / direction.y;
                (t > T_MIN && t <= limit).then(|| Hit {
                    t,
                    normal: Vector3::y() * -direction.y.signum(),
                    surface: Surface::Ground,
                })
            }
            Ground::HeightField(field) => field.cast(origin, direction, limit, hints.ground_height),
        };
        ground.or(best)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flat_ground_is_hit_at_the_height_over_the_downward_component() {
        let world = World::flat();
        let origin = Point3::new(0.3, 1.2, -0.4);
        let direction = Vector3::new(0.6, -0.8, 0.0);
        let t = world.hit(&origin, &direction).unwrap();
        assert!((t - 1.5).abs() < 1e-12);
        assert_eq!(world.hit(&origin, &Vector3::new(1.0, 0.1, 0.0)), None);
        assert_eq!(world.hit(&origin, &Vector3::new(1.0, 0.0, 0.0)), None);
    }

    #[test]
    fn box_top_and_side_are_hit_exactly() {
        let b = BoxObstacle {
            centre_x: 2.0,
            centre_z: 0.0,
            half_x: 0.2,
            half_z: 0.3,
            height: 0.25,
            yaw: 0.0,
        };
        let world = World {
            ground: Ground::Flat,
            boxes: vec![b],
            walls: vec![],
        };
        // Straight down onto the top.
        let hit = world
            .cast(&Point3::new(2.05, 1.0, 0.1), &-Vector3::y(), f64::INFINITY)
            .unwrap();
        assert_eq!(hit.surface, Surface::Box(0));
        assert!((hit.t - 0.75).abs() < 1e-12);
        assert!((hit.normal - Vector3::y()).norm() < 1e-12);
        // Horizontally onto the near side.
        let hit = world
            .cast(&Point3::new(0.0, 0.1, 0.0), &Vector3::x(), f64::INFINITY)
            .unwrap();
        assert!((hit.t - 1.8).abs() < 1e-12);
        assert!((hit.normal + Vector3::x()).norm() < 1e-12);
        // Just past the side the ray reaches nothing.
        assert_eq!(world.hit(&Point3::new(0.0, 0.1, 0.31), &Vector3::x()), None);
    }

    #[test]
    fn rotated_box_is_hit_on_its_rotated_face() {
        let yaw = 30f64.to_radians();
        let b = BoxObstacle {
            centre_x: 0.0,
            centre_z: 0.0,
            half_x: 0.5,
            half_z: 0.5,
            height: 1.0,
            yaw,
        };
        let world = World {
            ground: Ground::Flat,
            boxes: vec![b],
            walls: vec![],
        };
        // The box's +x face has the normal Ry(yaw)·x = (cos, 0, -sin); aim at it.
        let face_normal = Vector3::new(yaw.cos(), 0.0, -yaw.sin());
        let origin = Point3::from(face_normal * 3.0 + Vector3::y() * 0.5);
        let hit = world.cast(&origin, &-face_normal, f64::INFINITY).unwrap();
        assert!((hit.t - 2.5).abs() < 1e-12);
        assert!((hit.normal - face_normal).norm() < 1e-12);
    }

    #[test]
    fn wall_is_finite_and_seen_from_both_sides() {
        let wall = Wall {
            start: Vector2::new(3.0, -1.0),
            end: Vector2::new(3.0, 1.0),
            height: 1.0,
        };
        let world = World {
            ground: Ground::Flat,
            boxes: vec![],
            walls: vec![wall],
        };
        let hit = world
            .cast(&Point3::new(0.0, 0.5, 0.0), &Vector3::x(), f64::INFINITY)
            .unwrap();
        assert_eq!(hit.surface, Surface::Wall(0));
        assert!((hit.t - 3.0).abs() < 1e-12);
        assert!((hit.normal + Vector3::x()).norm() < 1e-12);
        let hit = world
            .cast(&Point3::new(5.0, 0.5, 0.0), &-Vector3::x(), f64::INFINITY)
            .unwrap();
        assert!((hit.t - 2.0).abs() < 1e-12);
        assert!((hit.normal - Vector3::x()).norm() < 1e-12);
        // Over the top and past the end.
        assert_eq!(world.hit(&Point3::new(0.0, 1.1, 0.0), &Vector3::x()), None);
        assert_eq!(world.hit(&Point3::new(0.0, 0.5, 1.1), &Vector3::x()), None);
        // The t cap hides it.
        assert_eq!(
            world.cast(&Point3::new(0.0, 0.5, 0.0), &Vector3::x(), 2.9),
            None
        );
    }

    #[test]
    fn nearest_surface_wins() {
        let world = World::boxes_and_wall(7);
        let b = world.boxes[0];
        // From above the box's centre, down: the box top, not the ground.
        let origin = Point3::new(b.centre_x, 1.0, b.centre_z);
        let t = world.hit(&origin, &-Vector3::y()).unwrap();
        assert!((t - (1.0 - b.height)).abs() < 1e-12);
    }

    #[test]
    fn seeded_worlds_are_deterministic_and_within_their_ranges() {
        assert_eq!(World::boxes_and_wall(3), World::boxes_and_wall(3));
        assert_ne!(World::boxes_and_wall(3), World::boxes_and_wall(4));
        assert_eq!(World::uneven(3, 0.01), World::uneven(3, 0.01));
        for seed in 0..50 {
            let world = World::boxes_and_wall(seed);
            assert_eq!(world.boxes.len(), 2);
            for b in &world.boxes {
                assert!((0.1..=0.4).contains(&b.height));
            }
            let w = world.walls[0];
            let x = (w.start.x + w.end.x) / 2.0;
            assert!((2.5..=3.5).contains(&x));
        }
    }

    #[test]
    fn height_field_hits_lie_on_the_surface_and_are_the_first() {
        let world = World::uneven(11, 0.02);
        let Ground::HeightField(field) = &world.ground else {
            unreachable!()
        };
        assert!((field.max_height() - 0.02).abs() < 1e-12);
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut hits = 0;
        for _ in 0..2000 {
            let origin = Point3::new(rng.gen_range(-1.0..1.0), rng.gen_range(0.3..1.5), 0.0);
            // Downward rays from steep to grazing (2° below the horizon).
            let down = rng.gen_range(2f64.to_radians()..80f64.to_radians());
            let heading = rng.gen_range(0.0..std::f64::consts::TAU);
            let direction = Vector3::new(
                down.cos() * heading.cos(),
                -down.sin(),
                down.cos() * heading.sin(),
            );
            let Some(hit) = world.cast(&origin, &direction, 60.0) else {
                continue;
            };
            hits += 1;
            let p = origin + direction * hit.t;
            assert!(
                (p.y - field.height(p.x, p.z)).abs() < 1e-9,
                "hit {} m off the surface",
                p.y - field.height(p.x, p.z)
            );
            // No earlier crossing: the ray stays above the surface before it.
            for k in 1..200 {
                let q = origin + direction * (hit.t * k as f64 / 200.0);
                assert!(q.y - field.height(q.x, q.z) > -1e-9);
            }
            assert!(hit.normal.y > 0.9);
        }
        assert!(hits > 1900, "only {hits} of 2000 rays hit the ground");
    }

    #[test]
    fn height_field_amplitude_bounds_the_surface() {
        let field = HeightField::seeded(2, 0.015);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut largest: f64 = 0.0;
        for _ in 0..10_000 {
            let h = field.height(rng.gen_range(-5.0..5.0), rng.gen_range(-5.0..5.0));
            largest = largest.max(h.abs());
        }
        assert!(largest <= 0.015 + 1e-12);
        // And it is not flat: at least a third of the bound is reached.
        assert!(largest > 0.005, "largest {largest}");
    }

    #[test]
    fn hints_save_work_without_changing_hits() {
        let world = World::uneven(4, 0.02);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for _ in 0..2000 {
            let origin = Point3::new(0.5, rng.gen_range(0.8..1.2), 0.0);
            let down = rng.gen_range(10f64.to_radians()..60f64.to_radians());
            let heading = rng.gen_range(-0.5..0.5f64);
            let direction = Vector3::new(
                down.cos() * heading.cos(),
                -down.sin(),
                down.cos() * heading.sin(),
            );
            let plain = world.cast(&origin, &direction, 10.0).unwrap();
            for guess in [-0.02, 0.0, 0.013, 0.02] {
                let hints = RayHints {
                    ground_height: Some(guess),
                    ..RayHints::default()
                };
                let hinted = world.cast_with(&origin, &direction, 10.0, &hints).unwrap();
                assert!((hinted.t - plain.t).abs() < 1e-10);
                assert!((hinted.normal - plain.normal).norm() < 1e-6);
            }
        }
        // Candidates: an obstacle left out is not hit, one left in is.
        let world = World::boxes_and_wall(7);
        let b = world.boxes[1];
        let origin = Point3::new(b.centre_x, 1.0, b.centre_z);
        let only = |candidates| {
            let hints = RayHints {
                candidates,
                ground_height: None,
            };
            world
                .cast_with(&origin, &-Vector3::y(), 10.0, &hints)
                .unwrap()
                .surface
        };
        assert_eq!(only(0b10), Surface::Box(1));
        assert_eq!(only(0b01), Surface::Ground);
        assert!(world.blocked_by_obstacle_among(&origin, &-Vector3::y(), 10.0, 0b10));
        assert!(!world.blocked_by_obstacle_among(&origin, &-Vector3::y(), 10.0, 0b101));
    }

    #[test]
    fn obstacle_corners_hold_the_obstacles() {
        let world = World::boxes_and_wall(5);
        let corners = world.obstacle_corners();
        assert_eq!(corners.len(), 3);
        for (b, c) in world.boxes.iter().zip(&corners) {
            assert_eq!(c.len(), 8);
            // Each corner is a corner of the footprint, at the bottom or top.
            for p in c {
                let d = Vector2::new(p.x - b.centre_x, p.z - b.centre_z).norm();
                let half_diagonal = (b.half_x.powi(2) + b.half_z.powi(2)).sqrt();
                assert!((d - half_diagonal).abs() < 1e-12);
                assert!(p.y == 0.0 || p.y == b.height);
            }
        }
        assert_eq!(corners[2].len(), 4);
    }
}
