//! The bird's-eye view of a frame's cones (plotters, PNG): the vehicle frame from above with
//! its axes in metres, the ground grid, the camera's field of view, each estimate with its
//! 3-sigma ellipse, and the true cones when the source is the renderer. The view reaches as
//! far as the farthest cone (32 m at least, 120 m at most). `draw.rs` draws the frame beside
//! it.

use std::path::Path;
use std::sync::OnceLock;

use conesight_core::cone::ConeClass;
use conesight_proto::LocatedCone;
use image::Rgb;
use nalgebra::{Matrix2, Matrix3, Point3, SymmetricEigen};
use plotters::prelude::*;
use plotters::style::FontStyle;

use crate::draw::class_colour;

/// One cone to plot, vehicle frame (x forward, y left).
#[derive(Debug, Clone, PartialEq)]
pub struct BevCone {
    /// Colour of its disc.
    pub class: ConeClass,
    /// Where the cone is, when known (the renderer's truth).
    pub truth_in_vehicle: Option<Point3<f64>>,
    /// Where the solver put it.
    pub estimate_in_vehicle: Point3<f64>,
    /// Covariance of the estimate, vehicle frame, m^2.
    pub covariance_in_vehicle: Matrix3<f64>,
}

impl BevCone {
    /// A located cone, without truth.
    pub fn estimate(cone: &LocatedCone) -> Self {
        Self {
            class: cone.detection.class,
            truth_in_vehicle: None,
            estimate_in_vehicle: cone.position_in_vehicle,
            covariance_in_vehicle: cone.covariance_in_vehicle_m2,
        }
    }
}

/// Plot size in pixels.
const SIZE_PX: u32 = 900;
/// Metres shown ahead of the vehicle at least (half as many to each side).
const AHEAD_M: f64 = 32.0;
/// Metres shown ahead at most: farther cones are counted in the caption, not drawn.
const MAX_AHEAD_M: f64 = 120.0;
/// The font of the plot's text (DejaVu Sans Mono, Bitstream Vera licence:
/// `assets/DejaVu-LICENSE.txt`), embedded so that a plot never depends on the fonts a host has.
static FONT: &[u8] = include_bytes!("../assets/DejaVuSansMono.ttf");

/// Registers [`FONT`] as plotters' sans-serif once per process.
pub(crate) fn register_font() -> anyhow::Result<()> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, FONT).is_ok()
    });
    anyhow::ensure!(ok, "the embedded plot font does not parse");
    Ok(())
}

/// Metres shown ahead for `cones`: the farthest (estimate or truth) with a margin, in steps of
/// 8 m, within [`AHEAD_M`, `MAX_AHEAD_M`].
fn reach_m(cones: &[BevCone]) -> f64 {
    let farthest = cones
        .iter()
        .flat_map(|c| std::iter::once(c.estimate_in_vehicle).chain(c.truth_in_vehicle))
        .map(|p| p.x.max(2.0 * p.y.abs()))
        .filter(|x| x.is_finite())
        .fold(0.0, f64::max);
    (((farthest + 4.0) / 8.0).ceil() * 8.0).clamp(AHEAD_M, MAX_AHEAD_M)
}

/// The 3-sigma ellipse of the horizontal (x, y) part of a covariance, as plot points
/// (plot x = -y, plot y = x) in metres.
fn ellipse(centre_m: &Point3<f64>, covariance: &Matrix3<f64>) -> Vec<(f64, f64)> {
    let horizontal = Matrix2::new(
        covariance[(0, 0)],
        covariance[(0, 1)],
        covariance[(1, 0)],
        covariance[(1, 1)],
    );
    let eigen = SymmetricEigen::new(horizontal);
    let axes = eigen.eigenvectors;
    let radii = eigen.eigenvalues.map(|v| 3.0 * v.max(0.0).sqrt());
    (0..=72)
        .map(|i| {
            let angle = f64::from(i * 5).to_radians();
            let offset = axes.column(0) * (radii[0] * angle.cos())
                + axes.column(1) * (radii[1] * angle.sin());
            (-(centre_m.y + offset.y), centre_m.x + offset.x)
        })
        .collect()
}

fn plot_colour(class: ConeClass) -> RGBColor {
    let Rgb([r, g, b]) = class_colour(class);
    RGBColor(r, g, b)
}

fn class_label(class: ConeClass, truth: bool) -> String {
    let name = match class {
        ConeClass::Blue => "blue cone",
        ConeClass::Yellow => "yellow cone",
        ConeClass::Orange => "orange cone",
        ConeClass::LargeOrange => "large orange cone",
    };
    format!("{name} ({})", if truth { "truth" } else { "estimate" })
}

/// Writes the plot (plotters): the vehicle frame seen from above, x ahead up the page and y
/// left to the left, axes and grid in metres out to the farthest cone, the camera's horizontal
/// field of view (`(image width, fx)` in pixels, when known), each estimate's 3-sigma ellipse
/// and a legend. With truth, true cones are discs in their class colour and estimates black
/// crosses; without, the estimates are the discs. `unranged` cones the solver could not place
/// are counted in the caption, as are cones beyond the farthest reach shown.
pub fn write_bev_png(
    path: &Path,
    cones: &[BevCone],
    field_of_view: Option<(u32, f64)>,
    unranged: usize,
) -> anyhow::Result<()> {
    register_font()?;
    let ahead_m = reach_m(cones);
    let side_m = ahead_m / 2.0;
    let inside = |p: &Point3<f64>| p.x >= 0.0 && p.x <= ahead_m && p.y.abs() <= side_m;
    let with_truth = cones.iter().any(|c| c.truth_in_vehicle.is_some());
    let outside = cones
        .iter()
        .filter(|c| !inside(&c.estimate_in_vehicle))
        .count();
    let mut caption = "Cones from above, vehicle frame".to_owned();
    let mut notes = Vec::new();
    if unranged > 0 {
        notes.push(format!("{unranged} without a range"));
    }
    if outside > 0 {
        notes.push(format!("{outside} out of view"));
    }
    if !notes.is_empty() {
        caption = format!("{caption} ({} not shown)", notes.join(", "));
    }
    let draw = || -> Result<(), Box<dyn std::error::Error>> {
        let root = BitMapBackend::new(path, (SIZE_PX, SIZE_PX)).into_drawing_area();
        root.fill(&WHITE)?;
        // Plot x is -y (so left of the car is left on the page); its labels show y.
        let mut chart = ChartBuilder::on(&root)
            .caption(caption.as_str(), ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(56)
            .build_cartesian_2d(-side_m..side_m, 0.0..ahead_m)?;
        chart
            .configure_mesh()
            .x_desc("y: left of the car (m)")
            .y_desc("x: ahead of the car (m)")
            .x_labels(9)
            .x_label_formatter(&|v| format!("{:.0}", -v + 0.0))
            .y_label_formatter(&|v| format!("{v:.0}"))
            .y_labels(9)
            .label_style(("sans-serif", 15))
            .axis_desc_style(("sans-serif", 17))
            .light_line_style(RGBColor(235, 235, 235))
            .bold_line_style(RGBColor(205, 205, 205))
            .draw()?;

        if let Some((image_width_px, focal_px)) = field_of_view {
            let half_fov = (f64::from(image_width_px) / 2.0 / focal_px).atan();
            let reach = side_m.min(ahead_m * half_fov.tan());
            let fov = [
                (reach, reach / half_fov.tan()),
                (0.0, 0.0),
                (-reach, reach / half_fov.tan()),
            ];
            chart
                .draw_series(LineSeries::new(
                    fov,
                    RGBColor(110, 170, 110).stroke_width(2),
                ))?
                .label("camera field of view")
                .legend(|(x, y)| {
                    PathElement::new(
                        [(x, y), (x + 18, y)],
                        RGBColor(110, 170, 110).stroke_width(2),
                    )
                });
        }

        let disc_at = |c: &BevCone| {
            if with_truth {
                c.truth_in_vehicle
            } else {
                Some(c.estimate_in_vehicle)
            }
        };
        let mut classes: Vec<ConeClass> = cones.iter().map(|c| c.class).collect();
        classes.sort();
        classes.dedup();
        for class in classes {
            let colour = plot_colour(class);
            chart
                .draw_series(
                    cones
                        .iter()
                        .filter(|c| c.class == class)
                        .filter_map(disc_at)
                        .filter(inside)
                        .map(|p| Circle::new((-p.y, p.x), 6, colour.filled())),
                )?
                .label(class_label(class, with_truth))
                .legend(move |(x, y)| Circle::new((x + 9, y), 6, colour.filled()));
        }
        let grey = RGBColor(130, 130, 130);
        for (i, cone) in cones
            .iter()
            .filter(|c| inside(&c.estimate_in_vehicle))
            .enumerate()
        {
            let series = chart.draw_series(LineSeries::new(
                ellipse(&cone.estimate_in_vehicle, &cone.covariance_in_vehicle),
                grey,
            ))?;
            if i == 0 {
                series
                    .label("3-sigma ellipse of the estimate")
                    .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], grey));
            }
        }
        if with_truth {
            chart
                .draw_series(
                    cones
                        .iter()
                        .map(|c| c.estimate_in_vehicle)
                        .filter(inside)
                        .map(|p| Cross::new((-p.y, p.x), 5, BLACK.stroke_width(2))),
                )?
                .label("estimate")
                .legend(|(x, y)| Cross::new((x + 9, y), 5, BLACK.stroke_width(2)));
        }
        // Outside the camera's view, where no cone is ever drawn.
        draw_legend(&mut chart, SeriesLabelPosition::LowerRight)?;
        root.present()?;
        Ok(())
    };
    draw().map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))
}

/// The legend of every conesight plot: the series' labels at `position`, on a light box.
pub(crate) fn draw_legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    chart
        .configure_series_labels()
        .position(position)
        .label_font(("sans-serif", 15))
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(160, 160, 160))
        .draw()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    /// The plot is a real PNG with the car's frame the right way round: a blue cone 10 m ahead
    /// and 4 m left is drawn left of and below a yellow cone 20 m ahead and 4 m right, and the
    /// axis labels put dark text pixels in the left margin.
    #[test]
    fn bev_plot_places_cones_on_metre_axes() {
        let path = std::env::temp_dir().join(format!("conesight-bev-{}.png", std::process::id()));
        let cone = |class, x: f64, y: f64| BevCone {
            class,
            truth_in_vehicle: Some(Point3::new(x, y, 0.0)),
            estimate_in_vehicle: Point3::new(x + 0.3, y + 0.1, 0.0),
            covariance_in_vehicle: Matrix3::from_diagonal_element(0.01),
        };
        let cones = [
            cone(ConeClass::Blue, 10.0, 4.0),
            cone(ConeClass::Yellow, 20.0, -4.0),
        ];
        write_bev_png(&path, &cones, Some((1920, 2048.0)), 0).unwrap();
        let image = image::open(&path).unwrap().to_rgb8();
        let _ = std::fs::remove_file(&path);
        assert_eq!(image.dimensions(), (SIZE_PX, SIZE_PX));
        // Centre of the pixels of a class colour, leaving out the legend (bottom right).
        let centre = |class| {
            let colour = class_colour(class);
            let pixels: Vec<(f64, f64)> = image
                .enumerate_pixels()
                .filter(|(x, y, p)| **p == colour && !(*x > SIZE_PX / 2 && *y > SIZE_PX * 3 / 4))
                .map(|(x, y, _)| (f64::from(x), f64::from(y)))
                .collect();
            assert!(!pixels.is_empty(), "no {class:?} disc drawn");
            let n = pixels.len() as f64;
            (
                pixels.iter().map(|p| p.0).sum::<f64>() / n,
                pixels.iter().map(|p| p.1).sum::<f64>() / n,
            )
        };
        let (blue, yellow) = (centre(ConeClass::Blue), centre(ConeClass::Yellow));
        let middle = f64::from(SIZE_PX) / 2.0;
        assert!(
            blue.0 < middle && yellow.0 > middle,
            "left must be left: {blue:?} {yellow:?}"
        );
        assert!(
            yellow.1 < blue.1,
            "farther ahead must be higher: {blue:?} {yellow:?}"
        );
        // 10 m more ahead and 8 m across: about the same distance in pixels (equal scales).
        let (dx, dy) = (yellow.0 - blue.0, blue.1 - yellow.1);
        assert!(
            (dy / dx - 10.0 / 8.0).abs() < 0.2,
            "axes not to scale: {dx} x {dy} px"
        );
        let dark_in_left_margin = (0..50)
            .flat_map(|x| (0..SIZE_PX).map(move |y| (x, y)))
            .filter(|&(x, y)| image.get_pixel(x, y).0.iter().all(|c| *c < 90))
            .count();
        assert!(dark_in_left_margin > 50, "no axis labels drawn");
    }

    /// Without truth the estimates are the discs, and the view reaches the farthest cone: one
    /// at 70 m is drawn in the upper half (the view used to stop at 32 m); one at 500 m is left
    /// out and counted.
    #[test]
    fn estimates_alone_are_drawn_out_to_the_farthest_cone() {
        let path =
            std::env::temp_dir().join(format!("conesight-bev-far-{}.png", std::process::id()));
        let cone = |class, x: f64, y: f64| BevCone {
            class,
            truth_in_vehicle: None,
            estimate_in_vehicle: Point3::new(x, y, 0.0),
            covariance_in_vehicle: Matrix3::from_diagonal_element(0.04),
        };
        let cones = [
            cone(ConeClass::Blue, 10.0, 2.0),
            cone(ConeClass::Yellow, 70.0, -5.0),
            cone(ConeClass::Orange, 500.0, 0.0),
        ];
        assert_eq!(reach_m(&cones[..2]), 80.0);
        write_bev_png(&path, &cones, None, 2).unwrap();
        let image = image::open(&path).unwrap().to_rgb8();
        let _ = std::fs::remove_file(&path);
        let rows_of = |class| -> Vec<u32> {
            image
                .enumerate_pixels()
                .filter(|(x, y, p)| {
                    **p == class_colour(class) && !(*x > SIZE_PX / 2 && *y > SIZE_PX * 3 / 4)
                })
                .map(|(_, y, _)| y)
                .collect()
        };
        let yellow = rows_of(ConeClass::Yellow);
        assert!(!yellow.is_empty(), "the cone at 70 m is not drawn");
        assert!(yellow.iter().all(|y| *y < SIZE_PX / 2), "{yellow:?}");
        assert!(rows_of(ConeClass::Blue).iter().all(|y| *y > SIZE_PX / 2));
    }
}
