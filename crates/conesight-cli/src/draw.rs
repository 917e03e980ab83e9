//! What the pipeline found, drawn on its frame: the one drawing module behind every annotated
//! frame conesight makes (`conesight demo`, `predict --save`, `run --out` and the dashboard's
//! `/api/frame.jpg`), for any source.
//!
//! Each cone ([`DrawnCone`]) gets its box in its class colour, its 7 keypoints (magenta), and a
//! label on a tag of its class colour: class, score and range (`blue 0.93 11.4 m`). A cone the
//! solver could not place gets a crimson cross over its box and `no range` in its label on a
//! crimson tag. The bird's-eye view beside it is `bev.rs`; [`save_frame`] writes both.

use std::path::{Path, PathBuf};

use anyhow::Context;
use conesight_core::cone::ConeClass;
use conesight_proto::{ConeDetection, ConeKeypoints, LocatedCone};
use conesight_vision::PixelBox;
use image::{Rgb, RgbImage};
use nalgebra::Point2;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::bev::{BevCone, register_font, write_bev_png};

/// Colour of the keypoints.
pub const KEYPOINT_COLOUR: Rgb<u8> = Rgb([255, 0, 255]);
/// Colour of the cross over a cone without a range, and of its tag.
pub const NO_RANGE_COLOUR: Rgb<u8> = Rgb([220, 20, 60]);

/// The colour of a class in every picture (frames, bird's-eye views).
pub fn class_colour(class: ConeClass) -> Rgb<u8> {
    match class {
        ConeClass::Blue => Rgb([30, 80, 230]),
        ConeClass::Yellow => Rgb([235, 200, 0]),
        ConeClass::Orange => Rgb([255, 120, 0]),
        ConeClass::LargeOrange => Rgb([220, 70, 0]),
    }
}

/// One cone to draw on a frame.
#[derive(Debug, Clone, PartialEq)]
pub struct DrawnCone {
    /// Its class: the colour of its box and tag.
    pub class: ConeClass,
    /// The detector's score (1 for given boxes).
    pub score: f32,
    /// Its box, frame pixels.
    pub box_px: PixelBox,
    /// Its keypoints, frame pixels, when the keypoint stage ran on it.
    pub keypoints_px: Option<[Point2<f64>; 7]>,
    /// Its range, metres; `None` when the solver could not place it (marked with a cross).
    pub range_m: Option<f64>,
}

impl DrawnCone {
    /// A detection alone: no keypoints, no range.
    pub fn detection(detection: &ConeDetection) -> Self {
        Self {
            class: detection.class,
            score: detection.score,
            box_px: detection.box_px,
            keypoints_px: None,
            range_m: None,
        }
    }

    /// A cone with keypoints, placed at `range_m` (or not).
    pub fn keypoints(cone: &ConeKeypoints, range_m: Option<f64>) -> Self {
        Self {
            keypoints_px: Some(cone.observation.keypoints_px),
            range_m,
            ..Self::detection(&cone.detection)
        }
    }

    /// A located cone whose keypoints are not at hand.
    pub fn located(cone: &LocatedCone) -> Self {
        Self {
            range_m: Some(cone.estimate.range_m()),
            ..Self::detection(&cone.detection)
        }
    }
}

/// The cones of one frame as the bus carries them: every cone of the `keypoints` message (with
/// the range of the located cone of the same detection, else none: its ranging failed), and
/// the `located` cones whose keypoints are not there (e.g. a keypoints message that was missed).
pub fn cones_of_frame(keypoints: &[ConeKeypoints], located: &[LocatedCone]) -> Vec<DrawnCone> {
    let mut used = vec![false; located.len()];
    let mut cones: Vec<DrawnCone> = keypoints
        .iter()
        .map(|cone| {
            let found = located
                .iter()
                .enumerate()
                .find(|(i, l)| !used[*i] && l.detection == cone.detection);
            let range_m = found.map(|(i, l)| {
                used[i] = true;
                l.estimate.range_m()
            });
            DrawnCone::keypoints(cone, range_m)
        })
        .collect();
    cones.extend(
        located
            .iter()
            .zip(&used)
            .filter(|(_, used)| !**used)
            .map(|(cone, _)| DrawnCone::located(cone)),
    );
    cones
}

/// Where [`save_frame`] wrote a frame's pictures.
#[derive(Debug, Clone)]
pub struct SavedFrame {
    /// The annotated frame (PNG).
    pub frame: PathBuf,
    /// Its bird's-eye view (PNG).
    pub bev: PathBuf,
}

/// The camera's horizontal field of view for the bird's-eye view: (image width, fx), pixels.
pub type FieldOfView = Option<(u32, f64)>;

/// Writes `<dir>/<stem>.png` (the frame with `cones` drawn on it) and `<dir>/<stem>_bev.png`
/// (the cones of `bev` from above); `unranged` cones without a range are counted in the
/// view's caption.
pub fn save_frame(
    dir: &Path,
    stem: &str,
    image: &RgbImage,
    cones: &[DrawnCone],
    bev: &[BevCone],
    field_of_view: FieldOfView,
) -> anyhow::Result<SavedFrame> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut annotated = image.clone();
    annotate(&mut annotated, cones, 1.0)?;
    let frame = dir.join(format!("{stem}.png"));
    annotated
        .save(&frame)
        .with_context(|| format!("cannot write {}", frame.display()))?;
    let bev_path = dir.join(format!("{stem}_bev.png"));
    let unranged = cones.iter().filter(|c| c.range_m.is_none()).count();
    write_bev_png(&bev_path, bev, field_of_view, unranged)?;
    Ok(SavedFrame {
        frame,
        bev: bev_path,
    })
}

/// Draws `cones` on `image`, whose pixels are the frame's scaled by `scale` (the dashboard
/// draws on a frame shrunk to 960 px): boxes, keypoints and crosses first, then the labels,
/// the nearest cones' first, each above its box, else below it, else inside its top, wherever
/// it covers no label placed before (on a crowded frame it goes above regardless).
pub fn annotate(image: &mut RgbImage, cones: &[DrawnCone], scale: f64) -> anyhow::Result<()> {
    register_font()?;
    let (width, height) = image.dimensions();
    // Lines and text grow with the frame: 2 px and 18 px at 1080 rows, 1 px and 10 px at 540.
    let rows = f64::from(height);
    let stroke = ((rows / 540.0).round() as u32).clamp(1, 4);
    let font_px = (rows / 60.0).clamp(10.0, 28.0);
    let buffer: &mut [u8] = image;
    let backend = BitMapBackend::with_buffer_and_format(buffer, (width, height))
        .map_err(|e| anyhow::anyhow!("cannot draw on a {width}x{height} frame: {e}"))?;
    let root = backend.into_drawing_area();
    let px = |x: f64, y: f64| ((x * scale).round() as i32, (y * scale).round() as i32);
    let draw = |root: &DrawingArea<BitMapBackend, _>| -> Result<(), Box<dyn std::error::Error>> {
        for cone in cones {
            let b = &cone.box_px;
            let (x0, y0) = px(b.x_min_px, b.y_min_px);
            let (x1, y1) = px(b.x_max_px, b.y_max_px);
            root.draw(&PathElement::new(
                vec![(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)],
                rgb(class_colour(cone.class)).stroke_width(stroke),
            ))?;
            if let Some(keypoints) = &cone.keypoints_px {
                // Small enough that a far cone's 7 points stay apart.
                let radius =
                    ((f64::from(y1 - y0) / 25.0).round() as i32).clamp(1, stroke as i32 + 1);
                for p in keypoints {
                    root.draw(&Circle::new(
                        px(p.x, p.y),
                        radius,
                        rgb(KEYPOINT_COLOUR).filled(),
                    ))?;
                }
            }
            if cone.range_m.is_none() {
                let cross = rgb(NO_RANGE_COLOUR).stroke_width(stroke);
                root.draw(&PathElement::new(vec![(x0, y0), (x1, y1)], cross))?;
                root.draw(&PathElement::new(vec![(x0, y1), (x1, y0)], cross))?;
            }
        }
        let mut order: Vec<&DrawnCone> = cones.iter().collect();
        order.sort_by(|a, b| b.box_px.height_px().total_cmp(&a.box_px.height_px()));
        let mut placed: Vec<[i32; 4]> = Vec::new();
        for cone in order {
            let (label, tag) = match cone.range_m {
                Some(range_m) => (
                    format!("{} {:.2} {range_m:.1} m", cone.class.as_str(), cone.score),
                    rgb(class_colour(cone.class)),
                ),
                None => (
                    format!("{} {:.2} no range", cone.class.as_str(), cone.score),
                    rgb(NO_RANGE_COLOUR),
                ),
            };
            let ink = if cone.class == ConeClass::Yellow && cone.range_m.is_some() {
                BLACK
            } else {
                WHITE
            };
            let style = TextStyle::from(("sans-serif", font_px).into_font())
                .color(&ink)
                .pos(Pos::new(HPos::Left, VPos::Top));
            let (text_w, text_h) = root.estimate_text_size(&label, &style)?;
            let (tag_w, tag_h) = (text_w as i32 + 6, text_h as i32 + 4);
            let b = &cone.box_px;
            let (x0, y0) = px(b.x_min_px, b.y_min_px);
            let (_, y1) = px(b.x_max_px, b.y_max_px);
            let x = x0.clamp(0, (width as i32 - tag_w).max(0));
            let candidates = [y0 - tag_h - stroke as i32, y1 + stroke as i32, y0]
                .map(|y| y.clamp(0, (height as i32 - tag_h).max(0)));
            let overlaps = |top: i32| {
                placed.iter().any(|[px0, py0, px1, py1]| {
                    x < *px1 && x + tag_w > *px0 && top < *py1 && top + tag_h > *py0
                })
            };
            let top = candidates
                .iter()
                .copied()
                .find(|top| !overlaps(*top))
                .unwrap_or(candidates[0]);
            placed.push([x, top, x + tag_w, top + tag_h]);
            root.draw(&Rectangle::new(
                [(x, top), (x + tag_w, top + tag_h)],
                tag.mix(0.85).filled(),
            ))?;
            root.draw(&Text::new(label, (x + 3, top + 2), style))?;
        }
        root.present()?;
        Ok(())
    };
    draw(&root).map_err(|e| anyhow::anyhow!("cannot draw on the frame: {e}"))
}

fn rgb(Rgb([r, g, b]): Rgb<u8>) -> RGBColor {
    RGBColor(r, g, b)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn cone(class: ConeClass, x: f64, range_m: Option<f64>) -> DrawnCone {
        DrawnCone {
            class,
            score: 0.9,
            box_px: PixelBox {
                x_min_px: x,
                y_min_px: 200.0,
                x_max_px: x + 40.0,
                y_max_px: 260.0,
            },
            keypoints_px: Some([Point2::new(x + 20.0, 230.0); 7]),
            range_m,
        }
    }

    fn count(image: &RgbImage, colour: Rgb<u8>, x: std::ops::Range<u32>) -> usize {
        image
            .enumerate_pixels()
            .filter(|(px, _, p)| x.contains(px) && **p == colour)
            .count()
    }

    /// Each box in its class colour, its keypoints, its tag, and a crimson cross and tag where
    /// the range is missing; nothing outside the cones.
    #[test]
    fn cones_are_drawn_in_their_colours_with_a_mark_where_ranging_failed() {
        let mut image = RgbImage::from_pixel(640, 400, Rgb([90, 90, 90]));
        let cones = [
            cone(ConeClass::Blue, 50.0, Some(11.4)),
            cone(ConeClass::Yellow, 300.0, None),
        ];
        annotate(&mut image, &cones, 1.0).unwrap();
        assert!(count(&image, class_colour(ConeClass::Blue), 40..260) > 100);
        assert!(count(&image, class_colour(ConeClass::Yellow), 290..520) > 100);
        assert!(count(&image, KEYPOINT_COLOUR, 40..100) > 5);
        assert!(
            count(&image, NO_RANGE_COLOUR, 40..260) == 0,
            "blue has a range"
        );
        // The cross's diagonals are anti-aliased: count the pixels it reddened.
        let reddened = image
            .enumerate_pixels()
            .filter(|(x, _, p)| {
                let [r, g, b] = p.0.map(i32::from);
                (290..520).contains(x) && r - g > 60 && r - b > 40
            })
            .count();
        assert!(reddened > 80, "no cross: {reddened} red pixels");
        // The corners of the frame are untouched.
        assert_eq!(*image.get_pixel(630, 390), Rgb([90, 90, 90]));
    }

    /// The dashboard's frame is shrunk: the boxes follow.
    #[test]
    fn scale_moves_the_boxes_with_the_frame() {
        let mut image = RgbImage::from_pixel(320, 200, Rgb([0, 0, 0]));
        annotate(&mut image, &[cone(ConeClass::Blue, 400.0, Some(5.0))], 0.5).unwrap();
        assert!(count(&image, class_colour(ConeClass::Blue), 195..225) > 40);
        assert_eq!(count(&image, class_colour(ConeClass::Blue), 0..190), 0);
    }
}
