//! A bird's-eye-view plot of true and estimated cones (plotters, PNG), and the small drawing
//! helpers the annotated frames use.

use std::path::Path;
use std::sync::OnceLock;

use conesight_core::cone::ConeClass;
use image::{Rgb, RgbImage};
use nalgebra::{Matrix2, Matrix3, Point3, SymmetricEigen};
use plotters::prelude::*;
use plotters::style::FontStyle;

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
const SIZE_PX: u32 = 900;
/// Metres shown ahead of the vehicle.
const AHEAD_M: f64 = 32.0;
/// Metres shown to each side.
const SIDE_M: f64 = 16.0;
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

/// Annotated frames: a line straight into the image.
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

/// Annotated frames: a filled disc straight into the image.
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

fn class_label(class: ConeClass) -> &'static str {
    match class {
        ConeClass::Blue => "blue cone (truth)",
        ConeClass::Yellow => "yellow cone (truth)",
        ConeClass::Orange => "orange cone (truth)",
        ConeClass::LargeOrange => "large orange cone (truth)",
    }
}

/// Writes the plot (plotters): the vehicle frame seen from above, x ahead up the page and y
/// left to the left, axes and grid in metres, the camera's horizontal field of view, true
/// cones as discs in their class colour, estimates as black crosses with their 3-sigma
/// ellipses, and a legend.
pub fn write_bev_png(
    path: &Path,
    cones: &[BevCone],
    image_width_px: u32,
    focal_px: f64,
) -> anyhow::Result<()> {
    register_font()?;
    let draw = || -> Result<(), Box<dyn std::error::Error>> {
        let root = BitMapBackend::new(path, (SIZE_PX, SIZE_PX)).into_drawing_area();
        root.fill(&WHITE)?;
        // Plot x is -y (so left of the car is left on the page); its labels show y.
        let mut chart = ChartBuilder::on(&root)
            .caption("Cones from above, vehicle frame", ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(56)
            .build_cartesian_2d(-SIDE_M..SIDE_M, 0.0..AHEAD_M)?;
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

        let half_fov = (f64::from(image_width_px) / 2.0 / focal_px).atan();
        let reach = SIDE_M.min(AHEAD_M * half_fov.tan());
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

        let mut classes: Vec<ConeClass> = cones.iter().map(|c| c.class).collect();
        classes.sort();
        classes.dedup();
        for class in classes {
            let colour = plot_colour(class);
            chart
                .draw_series(cones.iter().filter(|c| c.class == class).map(|c| {
                    Circle::new(
                        (-c.truth_in_vehicle.y, c.truth_in_vehicle.x),
                        6,
                        colour.filled(),
                    )
                }))?
                .label(class_label(class))
                .legend(move |(x, y)| Circle::new((x + 9, y), 6, colour.filled()));
        }
        let grey = RGBColor(130, 130, 130);
        for (i, cone) in cones.iter().enumerate() {
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
        chart
            .draw_series(cones.iter().map(|c| {
                Cross::new(
                    (-c.estimate_in_vehicle.y, c.estimate_in_vehicle.x),
                    5,
                    BLACK.stroke_width(2),
                )
            }))?
            .label("estimate")
            .legend(|(x, y)| Cross::new((x + 9, y), 5, BLACK.stroke_width(2)));
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
            truth_in_vehicle: Point3::new(x, y, 0.0),
            estimate_in_vehicle: Point3::new(x + 0.3, y + 0.1, 0.0),
            covariance_in_vehicle: Matrix3::from_diagonal_element(0.01),
        };
        let cones = [
            cone(ConeClass::Blue, 10.0, 4.0),
            cone(ConeClass::Yellow, 20.0, -4.0),
        ];
        write_bev_png(&path, &cones, 1920, 2048.0).unwrap();
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
}
