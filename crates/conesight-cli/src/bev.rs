//! A bird's-eye-view plot of true and estimated cones, drawn straight into a PNG.

use std::path::Path;

use anyhow::Context;
use conesight_core::cone::ConeClass;
use image::{Rgb, RgbImage};
use nalgebra::{Matrix2, Matrix3, Point3, SymmetricEigen};

/// One cone to plot, vehicle frame (x forward, y left).
pub struct BevCone {
    /// Colour of the disc.
    pub class: ConeClass,
    /// Where the cone is.
    pub truth_in_vehicle: Point3<f64>,
    /// Where the solver put it.
    pub estimate_in_vehicle: Point3<f64>,
    /// Covariance of the estimate, vehicle frame, m^2.
    pub covariance_in_vehicle: Matrix3<f64>,
}

/// Plot size in pixels.
const SIZE_PX: u32 = 800;
/// Metres shown ahead of the vehicle.
const AHEAD_M: f64 = 32.0;
/// Pixels per metre.
const SCALE: f64 = SIZE_PX as f64 / AHEAD_M;
/// Grid spacing, metres.
const GRID_M: f64 = 5.0;

/// Plot pixel of a vehicle-frame point: x forward is up, y left is left; the vehicle sits at
/// the bottom centre.
fn to_px(x_m: f64, y_m: f64) -> (f64, f64) {
    (
        f64::from(SIZE_PX) / 2.0 - y_m * SCALE,
        f64::from(SIZE_PX) - 4.0 - x_m * SCALE,
    )
}

pub(crate) fn class_colour(class: ConeClass) -> Rgb<u8> {
    match class {
        ConeClass::Blue => Rgb([30, 80, 230]),
        ConeClass::Yellow => Rgb([235, 200, 0]),
        ConeClass::Orange => Rgb([255, 120, 0]),
        ConeClass::LargeOrange => Rgb([220, 70, 0]),
    }
}

fn put(image: &mut RgbImage, x: f64, y: f64, colour: Rgb<u8>) {
    if x >= 0.0 && y >= 0.0 && x < f64::from(image.width()) && y < f64::from(image.height()) {
        // Truncation is the intended pixel lookup here.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        image.put_pixel(x as u32, y as u32, colour);
    }
}

pub(crate) fn line(image: &mut RgbImage, from: (f64, f64), to: (f64, f64), colour: Rgb<u8>) {
    let steps = (to.0 - from.0)
        .abs()
        .max((to.1 - from.1).abs())
        .ceil()
        .max(1.0);
    let n = steps as usize;
    for i in 0..=n {
        let t = i as f64 / steps;
        put(
            image,
            from.0 + t * (to.0 - from.0),
            from.1 + t * (to.1 - from.1),
            colour,
        );
    }
}

pub(crate) fn disc(image: &mut RgbImage, centre: (f64, f64), radius_px: f64, colour: Rgb<u8>) {
    let r = radius_px.ceil() as i64;
    for dy in -r..=r {
        for dx in -r..=r {
            let (dx, dy) = (dx as f64, dy as f64);
            if dx * dx + dy * dy <= radius_px * radius_px {
                put(image, centre.0 + dx, centre.1 + dy, colour);
            }
        }
    }
}

/// The 3-sigma ellipse of the horizontal (x, y) part of a covariance.
fn ellipse(image: &mut RgbImage, centre_m: &Point3<f64>, covariance: &Matrix3<f64>) {
    let horizontal = Matrix2::new(
        covariance[(0, 0)],
        covariance[(0, 1)],
        covariance[(1, 0)],
        covariance[(1, 1)],
    );
    let eigen = SymmetricEigen::new(horizontal);
    let axes = eigen.eigenvectors;
    let radii = eigen.eigenvalues.map(|v| 3.0 * v.max(0.0).sqrt());
    for i in 0..360 {
        let angle = f64::from(i).to_radians();
        let offset =
            axes.column(0) * (radii[0] * angle.cos()) + axes.column(1) * (radii[1] * angle.sin());
        let (x, y) = to_px(centre_m.x + offset.x, centre_m.y + offset.y);
        put(image, x, y, Rgb([120, 120, 120]));
    }
}

/// Writes the plot: grid every 5 m, the camera's horizontal field of view, true cones as discs
/// in their colour, estimates as black crosses with 3-sigma ellipses.
pub fn write_bev_png(
    path: &Path,
    cones: &[BevCone],
    image_width_px: u32,
    focal_px: f64,
) -> anyhow::Result<()> {
    let mut image = RgbImage::from_pixel(SIZE_PX, SIZE_PX, Rgb([250, 250, 250]));
    let grid = Rgb([215, 215, 215]);
    let mut metre = 0.0;
    while metre <= AHEAD_M {
        line(&mut image, to_px(metre, 20.0), to_px(metre, -20.0), grid);
        line(
            &mut image,
            to_px(0.0, metre - 15.0),
            to_px(AHEAD_M, metre - 15.0),
            grid,
        );
        metre += GRID_M;
    }
    let half_fov = (f64::from(image_width_px) / 2.0 / focal_px).atan();
    for side in [-1.0, 1.0] {
        let far = AHEAD_M / half_fov.cos();
        line(
            &mut image,
            to_px(0.0, 0.0),
            to_px(far * half_fov.cos(), side * far * half_fov.sin()),
            Rgb([160, 200, 160]),
        );
    }
    for cone in cones {
        disc(
            &mut image,
            to_px(cone.truth_in_vehicle.x, cone.truth_in_vehicle.y),
            5.0,
            class_colour(cone.class),
        );
    }
    for cone in cones {
        ellipse(
            &mut image,
            &cone.estimate_in_vehicle,
            &cone.covariance_in_vehicle,
        );
        let (x, y) = to_px(cone.estimate_in_vehicle.x, cone.estimate_in_vehicle.y);
        line(
            &mut image,
            (x - 4.0, y - 4.0),
            (x + 4.0, y + 4.0),
            Rgb([0, 0, 0]),
        );
        line(
            &mut image,
            (x - 4.0, y + 4.0),
            (x + 4.0, y - 4.0),
            Rgb([0, 0, 0]),
        );
    }
    image
        .save(path)
        .with_context(|| format!("cannot write {}", path.display()))
}
