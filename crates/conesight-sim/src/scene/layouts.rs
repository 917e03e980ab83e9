//! Fixed Formula Student layouts: acceleration and skidpad (dimensions from the FSG rules).

use conesight_core::cone::ConeClass;
use nalgebra::Point2;
use std::f64::consts::TAU;

use super::track::{Track, TrackCone};

/// Acceleration straight length (start to finish line), metres.
pub const ACCELERATION_LENGTH_M: f64 = 75.0;
/// Braking zone after the finish line, metres.
pub const ACCELERATION_BRAKING_M: f64 = 75.0;
/// Cone spacing along the acceleration straight, metres.
const ACCELERATION_SPACING_M: f64 = 5.0;
/// Skidpad inner circle diameter, metres.
pub const SKIDPAD_INNER_DIAMETER_M: f64 = 15.25;
/// Skidpad outer circle diameter, metres.
pub const SKIDPAD_OUTER_DIAMETER_M: f64 = 21.25;
/// Distance between the skidpad circle centres, metres.
pub const SKIDPAD_CENTRE_DISTANCE_M: f64 = 18.25;

/// The acceleration layout: a straight along +x from the start line at x = 0, blue on the left
/// (+y), yellow on the right, large orange at start and finish, small orange along the braking
/// zone. The centreline runs from 10 m before the start to the end of the braking zone.
pub fn acceleration(width_m: f64) -> Track {
    let half = 0.5 * width_m;
    let mut cones = Vec::new();
    let mut push = |class, x: f64, y: f64| {
        cones.push(TrackCone {
            class,
            position_m: Point2::new(x, y),
        });
    };
    for x in [
        -0.6,
        0.6,
        ACCELERATION_LENGTH_M - 0.6,
        ACCELERATION_LENGTH_M + 0.6,
    ] {
        push(ConeClass::LargeOrange, x, half);
        push(ConeClass::LargeOrange, x, -half);
    }
    let mut x = ACCELERATION_SPACING_M;
    while x < ACCELERATION_LENGTH_M - 1.0 {
        push(ConeClass::Blue, x, half);
        push(ConeClass::Yellow, x, -half);
        x += ACCELERATION_SPACING_M;
    }
    let mut x = ACCELERATION_LENGTH_M + ACCELERATION_SPACING_M;
    while x <= ACCELERATION_LENGTH_M + ACCELERATION_BRAKING_M {
        push(ConeClass::Orange, x, half);
        push(ConeClass::Orange, x, -half);
        x += ACCELERATION_SPACING_M;
    }
    let end = ACCELERATION_LENGTH_M + ACCELERATION_BRAKING_M;
    let centreline_m = (0..=((end + 10.0) / 0.5) as usize)
        .map(|i| Point2::new(-10.0 + 0.5 * i as f64, 0.0))
        .collect();
    Track {
        name: "acceleration".to_owned(),
        centreline_m,
        closed: false,
        width_m,
        cones,
    }
}

/// The skidpad: two circles whose centres lie on the y axis, 18.25 m apart, touching the
/// x axis at the origin (the timing line). The car enters along +x, drives the right circle
/// twice clockwise, the left circle twice counter-clockwise, and leaves along +x. Inner cones of
/// the right circle are yellow (on the car's right), of the left circle blue; outer cones the
/// other colour; entry and exit lanes are small orange, the timing line large orange.
pub fn skidpad() -> Track {
    let centre_offset = 0.5 * SKIDPAD_CENTRE_DISTANCE_M;
    let r_in = 0.5 * SKIDPAD_INNER_DIAMETER_M;
    let r_out = 0.5 * SKIDPAD_OUTER_DIAMETER_M;
    let mut cones = Vec::new();
    for (centre_y, inner_class, outer_class) in [
        (-centre_offset, ConeClass::Yellow, ConeClass::Blue),
        (centre_offset, ConeClass::Blue, ConeClass::Yellow),
    ] {
        let centre = Point2::new(0.0, centre_y);
        for i in 0..16 {
            let a = TAU * f64::from(i) / 16.0;
            cones.push(TrackCone {
                class: inner_class,
                position_m: centre + nalgebra::Vector2::new(a.cos(), a.sin()) * r_in,
            });
        }
        for i in 0..13 {
            let a = TAU * (f64::from(i) + 0.5) / 13.0;
            let p = centre + nalgebra::Vector2::new(a.cos(), a.sin()) * r_out;
            // Outer cones in the crossing region would block the other circle.
            if p.y.abs() > 2.0 {
                cones.push(TrackCone {
                    class: outer_class,
                    position_m: p,
                });
            }
        }
    }
    let lane = 1.5;
    for x in [-15.0, -11.0, -7.0, -3.5, 3.5, 7.0, 11.0, 15.0] {
        for y in [lane, -lane] {
            cones.push(TrackCone {
                class: ConeClass::Orange,
                position_m: Point2::new(x, y),
            });
        }
    }
    for y in [lane + 0.6, -lane - 0.6] {
        cones.push(TrackCone {
            class: ConeClass::LargeOrange,
            position_m: Point2::new(0.0, y),
        });
    }
    // Centreline: entry, right circle x2 (clockwise), left circle x2, exit.
    let radius = 0.5 * (r_in + r_out);
    let mut centreline_m: Vec<Point2<f64>> = (0..30)
        .map(|i| Point2::new(-15.0 + 0.5 * f64::from(i), 0.0))
        .collect();
    let steps = 120;
    for (centre_y, sign) in [(-radius, 1.0), (radius, -1.0)] {
        for i in 0..(2 * steps) {
            let theta = TAU * f64::from(i) / f64::from(steps);
            centreline_m.push(Point2::new(
                radius * theta.sin(),
                centre_y + sign * radius * theta.cos(),
            ));
        }
    }
    centreline_m.extend((0..=30).map(|i| Point2::new(0.5 * f64::from(i), 0.0)));
    Track {
        name: "skidpad".to_owned(),
        centreline_m,
        closed: false,
        width_m: r_out - r_in,
        cones,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn acceleration_has_cones_every_five_metres_both_sides() {
        let track = acceleration(4.0);
        let blue: Vec<_> = track
            .cones
            .iter()
            .filter(|c| c.class == ConeClass::Blue)
            .collect();
        assert!(blue.iter().all(|c| c.position_m.y > 0.0));
        assert_eq!(blue.len(), 14);
        assert!(track.length_m() > ACCELERATION_LENGTH_M + ACCELERATION_BRAKING_M);
    }

    #[test]
    fn skidpad_inner_cones_are_on_the_right_dimensions() {
        let track = skidpad();
        let r_in = 0.5 * SKIDPAD_INNER_DIAMETER_M;
        let centre = Point2::new(0.0, -0.5 * SKIDPAD_CENTRE_DISTANCE_M);
        let inner_yellow = track
            .cones
            .iter()
            .filter(|c| ((c.position_m - centre).norm() - r_in).abs() < 1e-9)
            .filter(|c| c.class == ConeClass::Yellow)
            .count();
        assert_eq!(inner_yellow, 16);
        // The driven path passes between inner and outer circles.
        let pose = track.pose_at(30.0).unwrap();
        let d = (pose.position_m - centre).norm();
        assert!(d > r_in && d < 0.5 * SKIDPAD_OUTER_DIAMETER_M, "d = {d}");
    }
}
