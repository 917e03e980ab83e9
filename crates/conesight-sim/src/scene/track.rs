//! Track layouts: a centreline the car drives and the cones that bound it.
//!
//! [`Track::random_closed`] makes a random smooth closed circuit in the style of a Formula
//! Student autocross/trackdrive: blue cones on the left of the driving direction, yellow on the
//! right, at most [`MAX_CONE_SPACING_M`] apart along each edge, width at least
//! [`MIN_TRACK_WIDTH_M`], large orange cones at the start/finish line. Control points on a
//! jittered circle, some pulled deep inwards to make hairpins, joined by a closed Catmull-Rom
//! spline; candidates whose curvature is too tight or whose edges come too close are rejected.

use conesight_core::cone::ConeClass;
use nalgebra::{Point2, Vector2};
use rand::Rng;
use serde::Serialize;

/// Largest distance between neighbouring cones along a track edge, metres.
pub const MAX_CONE_SPACING_M: f64 = 5.0;
/// Smallest track width, metres.
pub const MIN_TRACK_WIDTH_M: f64 = 3.0;
/// Smallest radius of the centreline, metres (hairpins: 9 m outer diameter).
pub const MIN_CENTRELINE_RADIUS_M: f64 = 4.5;
/// Spacing of centreline samples, metres.
const CENTRELINE_STEP_M: f64 = 0.5;
/// Attempts at a random closed track before falling back to an oval.
const RANDOM_TRACK_ATTEMPTS: usize = 60;

/// One cone of a layout, on the ground plane of the world frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TrackCone {
    /// Class.
    pub class: ConeClass,
    /// Base centre in the world frame (x, y), metres.
    pub position_m: Point2<f64>,
}

/// A layout: the path the car drives and the cones.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Track {
    /// Layout name (`random`, `acceleration`, `skidpad`, `oval`).
    pub name: String,
    /// Centreline samples in the world frame, metres, in driving order.
    pub centreline_m: Vec<Point2<f64>>,
    /// True when the centreline closes on itself.
    pub closed: bool,
    /// Track width, metres.
    pub width_m: f64,
    /// The cones.
    pub cones: Vec<TrackCone>,
}

/// A pose on the centreline: position and heading (radians from the world x axis).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathPose {
    /// Position, metres.
    pub position_m: Point2<f64>,
    /// Heading, radians.
    pub heading_rad: f64,
}

impl Track {
    /// Length of the centreline, metres (including the closing segment of a closed track).
    pub fn length_m(&self) -> f64 {
        let n = self.centreline_m.len();
        let open: f64 = self
            .centreline_m
            .windows(2)
            .map(|w| (w[1] - w[0]).norm())
            .sum();
        if self.closed && n > 1 {
            open + (self.centreline_m[0] - self.centreline_m[n - 1]).norm()
        } else {
            open
        }
    }

    /// The pose at arc length `s_m` along the centreline (wrapping on a closed track, clamped
    /// to the ends of an open one). `None` for a centreline with fewer than two points.
    pub fn pose_at(&self, s_m: f64) -> Option<PathPose> {
        let points = &self.centreline_m;
        if points.len() < 2 {
            return None;
        }
        let length = self.length_m();
        let mut s = if self.closed {
            s_m.rem_euclid(length)
        } else {
            s_m.clamp(0.0, length)
        };
        let segments = if self.closed {
            points.len()
        } else {
            points.len() - 1
        };
        for i in 0..segments {
            let a = points[i];
            let b = points[(i + 1) % points.len()];
            let seg = (b - a).norm();
            if s <= seg || i + 1 == segments {
                let t = if seg > 0.0 { (s / seg).min(1.0) } else { 0.0 };
                let d = b - a;
                return Some(PathPose {
                    position_m: a + d * t,
                    heading_rad: d.y.atan2(d.x),
                });
            }
            s -= seg;
        }
        None
    }

    /// A random closed circuit; deterministic for the given generator. Falls back to an oval
    /// when no valid random candidate is found.
    pub fn random_closed(rng: &mut impl Rng) -> Self {
        let width_m = rng.random_range(MIN_TRACK_WIDTH_M..4.5);
        for _ in 0..RANDOM_TRACK_ATTEMPTS {
            let controls = random_controls(rng);
            let centreline = closed_spline(&controls, CENTRELINE_STEP_M);
            if is_valid_closed(&centreline, width_m) {
                return Self::from_closed_centreline("random", centreline, width_m, rng);
            }
        }
        Self::oval(width_m, rng)
    }

    /// A 30 m x 60 m stadium-shaped circuit.
    pub fn oval(width_m: f64, rng: &mut impl Rng) -> Self {
        let controls: Vec<Point2<f64>> = (0..12)
            .map(|i| {
                let a = std::f64::consts::TAU * f64::from(i) / 12.0;
                Point2::new(30.0 * a.cos(), 15.0 * a.sin())
            })
            .collect();
        let centreline = closed_spline(&controls, CENTRELINE_STEP_M);
        Self::from_closed_centreline("oval", centreline, width_m, rng)
    }

    /// Cones along both edges of a closed centreline, large orange at the start (s = 0).
    fn from_closed_centreline(
        name: &str,
        centreline_m: Vec<Point2<f64>>,
        width_m: f64,
        rng: &mut impl Rng,
    ) -> Self {
        let mut track = Self {
            name: name.to_owned(),
            centreline_m,
            closed: true,
            width_m,
            cones: Vec::new(),
        };
        let length = track.length_m();
        // Start/finish: two large orange cones on each side.
        for s in [-0.6, 0.6] {
            track.push_pair(s, ConeClass::LargeOrange, ConeClass::LargeOrange);
        }
        let mut s = 2.5;
        while s < length - 2.5 {
            track.push_pair(s, ConeClass::Blue, ConeClass::Yellow);
            let radius = track.radius_at(s).min(1e3);
            let wanted = (1.5 + 0.3 * radius) * rng.random_range(0.85..1.0);
            // Shrink the step until both edges stay under the spacing limit.
            let mut step = wanted.clamp(1.5, MAX_CONE_SPACING_M);
            while step > 1.0 && track.edge_gap_m(s, s + step) > 0.97 * MAX_CONE_SPACING_M {
                step *= 0.9;
            }
            s += step;
        }
        track
    }

    /// Adds a cone on each edge at arc length `s_m`.
    pub(crate) fn push_pair(&mut self, s_m: f64, left: ConeClass, right: ConeClass) {
        let Some(pose) = self.pose_at(s_m) else {
            return;
        };
        let normal_left = Vector2::new(-pose.heading_rad.sin(), pose.heading_rad.cos());
        let half = 0.5 * self.width_m;
        self.cones.push(TrackCone {
            class: left,
            position_m: pose.position_m + normal_left * half,
        });
        self.cones.push(TrackCone {
            class: right,
            position_m: pose.position_m - normal_left * half,
        });
    }

    /// Largest distance between the left (or right) edge points at `s0_m` and `s1_m`.
    fn edge_gap_m(&self, s0_m: f64, s1_m: f64) -> f64 {
        let edge = |s: f64, side: f64| {
            self.pose_at(s).map(|p| {
                let left = Vector2::new(-p.heading_rad.sin(), p.heading_rad.cos());
                p.position_m + left * (side * 0.5 * self.width_m)
            })
        };
        [1.0, -1.0]
            .iter()
            .filter_map(|side| Some((edge(s1_m, *side)? - edge(s0_m, *side)?).norm()))
            .fold(0.0, f64::max)
    }

    /// Radius of curvature of the centreline near `s_m`, metres (large on straights).
    fn radius_at(&self, s_m: f64) -> f64 {
        let (Some(a), Some(b)) = (self.pose_at(s_m - 1.0), self.pose_at(s_m + 1.0)) else {
            return f64::INFINITY;
        };
        let turn = wrap_angle(b.heading_rad - a.heading_rad).abs();
        if turn < 1e-6 { 1e6 } else { 2.0 / turn }
    }
}

/// Angle wrapped to `(-pi, pi]`.
pub fn wrap_angle(angle_rad: f64) -> f64 {
    let wrapped = (angle_rad + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU);
    wrapped - std::f64::consts::PI
}

/// Control points on a jittered circle; a few pulled inwards to make hairpins.
fn random_controls(rng: &mut impl Rng) -> Vec<Point2<f64>> {
    let count = rng.random_range(8..14);
    let radius = rng.random_range(35.0..60.0);
    let stretch = rng.random_range(0.6..1.0);
    (0..count)
        .map(|i| {
            let angle = std::f64::consts::TAU * (f64::from(i) + rng.random_range(-0.25..0.25))
                / f64::from(count);
            let r = if rng.random_bool(0.2) {
                radius * rng.random_range(0.35..0.55)
            } else {
                radius * rng.random_range(0.75..1.15)
            };
            Point2::new(r * angle.cos(), stretch * r * angle.sin())
        })
        .collect()
}

/// A closed centripetal Catmull-Rom spline through `controls`, resampled every `step_m`.
fn closed_spline(controls: &[Point2<f64>], step_m: f64) -> Vec<Point2<f64>> {
    let n = controls.len();
    let mut dense = Vec::new();
    for i in 0..n {
        let p0 = controls[(i + n - 1) % n];
        let p1 = controls[i];
        let p2 = controls[(i + 1) % n];
        let p3 = controls[(i + 2) % n];
        for k in 0..40 {
            dense.push(catmull_rom(p0, p1, p2, p3, f64::from(k) / 40.0));
        }
    }
    resample_closed(&dense, step_m)
}

/// Centripetal Catmull-Rom between `p1` and `p2` at `t` in [0, 1].
fn catmull_rom(
    p0: Point2<f64>,
    p1: Point2<f64>,
    p2: Point2<f64>,
    p3: Point2<f64>,
    t: f64,
) -> Point2<f64> {
    let knot = |a: Point2<f64>, b: Point2<f64>| (b - a).norm().sqrt().max(1e-6);
    let t0 = 0.0;
    let t1 = t0 + knot(p0, p1);
    let t2 = t1 + knot(p1, p2);
    let t3 = t2 + knot(p2, p3);
    let u = t1 + (t2 - t1) * t;
    let lerp = |a: Point2<f64>, b: Point2<f64>, ta: f64, tb: f64| {
        a.coords * ((tb - u) / (tb - ta)) + b.coords * ((u - ta) / (tb - ta))
    };
    let a1 = lerp(p0, p1, t0, t1);
    let a2 = lerp(p1, p2, t1, t2);
    let a3 = lerp(p2, p3, t2, t3);
    let b1 = a1 * ((t2 - u) / (t2 - t0)) + a2 * ((u - t0) / (t2 - t0));
    let b2 = a2 * ((t3 - u) / (t3 - t1)) + a3 * ((u - t1) / (t3 - t1));
    Point2::from(b1 * ((t2 - u) / (t2 - t1)) + b2 * ((u - t1) / (t2 - t1)))
}

/// Points every `step_m` of arc length along a closed polyline.
fn resample_closed(points: &[Point2<f64>], step_m: f64) -> Vec<Point2<f64>> {
    let n = points.len();
    let mut out = Vec::new();
    let mut carry = 0.0;
    for i in 0..n {
        let a = points[i];
        let b = points[(i + 1) % n];
        let seg = (b - a).norm();
        let mut s = carry;
        while s < seg {
            out.push(a + (b - a) * (s / seg));
            s += step_m;
        }
        carry = s - seg;
    }
    out
}

/// Curvature and clearance checks for a closed centreline.
fn is_valid_closed(centreline: &[Point2<f64>], width_m: f64) -> bool {
    let n = centreline.len();
    if n < 50 {
        return false;
    }
    // Curvature: turning angle over 2 m (4 samples) gives the radius.
    let span = (2.0 / CENTRELINE_STEP_M) as usize;
    for i in 0..n {
        let a = centreline[i];
        let b = centreline[(i + span / 2) % n];
        let c = centreline[(i + span) % n];
        let (d1, d2) = (b - a, c - b);
        let turn = wrap_angle(d2.y.atan2(d2.x) - d1.y.atan2(d1.x)).abs();
        let arc = d1.norm() + d2.norm();
        if turn > 1e-9 && arc / (2.0 * (0.5 * turn).sin()).max(1e-9) < MIN_CENTRELINE_RADIUS_M {
            return false;
        }
    }
    // Clearance between parts of the track far apart along it.
    let clearance = width_m + 3.0;
    let min_separation_samples = ((clearance * std::f64::consts::PI) / CENTRELINE_STEP_M) as usize;
    for i in 0..n {
        for j in (i + min_separation_samples)..n {
            let wrap_gap = n - (j - i);
            if wrap_gap < min_separation_samples {
                continue;
            }
            if (centreline[i] - centreline[j]).norm() < clearance {
                return false;
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{Purpose, stream};

    fn edge_spacing_ok(track: &Track, class: ConeClass) -> f64 {
        let cones: Vec<_> = track.cones.iter().filter(|c| c.class == class).collect();
        // Nearest neighbour distances along the edge: every cone has a neighbour within 5 m.
        cones
            .iter()
            .map(|a| {
                cones
                    .iter()
                    .filter(|b| b.position_m != a.position_m)
                    .map(|b| (a.position_m - b.position_m).norm())
                    .fold(f64::INFINITY, f64::min)
            })
            .fold(0.0, f64::max)
    }

    #[test]
    fn random_tracks_obey_the_rules_and_are_deterministic() {
        for seed in 0..4 {
            let track = Track::random_closed(&mut stream(seed, 0, Purpose::Track));
            let again = Track::random_closed(&mut stream(seed, 0, Purpose::Track));
            assert_eq!(track, again);
            assert!(track.width_m >= MIN_TRACK_WIDTH_M);
            assert!(track.length_m() > 100.0, "length {}", track.length_m());
            assert!(edge_spacing_ok(&track, ConeClass::Blue) <= MAX_CONE_SPACING_M + 1e-9);
            assert!(edge_spacing_ok(&track, ConeClass::Yellow) <= MAX_CONE_SPACING_M + 1e-9);
            let large = track
                .cones
                .iter()
                .filter(|c| c.class == ConeClass::LargeOrange)
                .count();
            assert_eq!(large, 4);
            // Blue on the left of the driving direction.
            let pose = track.pose_at(10.0).unwrap();
            let left = Vector2::new(-pose.heading_rad.sin(), pose.heading_rad.cos());
            let nearest_blue = track
                .cones
                .iter()
                .filter(|c| c.class == ConeClass::Blue)
                .min_by(|a, b| {
                    let da = (a.position_m - pose.position_m).norm();
                    let db = (b.position_m - pose.position_m).norm();
                    da.total_cmp(&db)
                })
                .unwrap();
            assert!((nearest_blue.position_m - pose.position_m).dot(&left) > 0.0);
        }
    }

    #[test]
    fn pose_at_wraps_on_closed_tracks() {
        let track = Track::oval(3.5, &mut stream(1, 0, Purpose::Track));
        let length = track.length_m();
        let a = track.pose_at(3.0).unwrap();
        let b = track.pose_at(3.0 + length).unwrap();
        assert!((a.position_m - b.position_m).norm() < 1e-6);
    }
}
