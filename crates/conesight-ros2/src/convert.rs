//! Between the bus's protobuf messages and their ROS 2 counterparts: cones out as
//! `conesight_msgs/ConeArray`, frames and calibration both ways (`sensor_msgs/Image`,
//! `CompressedImage`, `CameraInfo`).

use conesight_core::{Camera, ConeClass, Distortion, DistortionModel};
use conesight_proto::{ConeKeypoints, LocatedCone, pb};
use image::RgbImage;

use crate::Ros2Error;
use crate::msg::{
    CameraInfo, ColorRgba, CompressedImage, Cone, ConeArray, Duration, Header, Image, Keypoint,
    Marker, MarkerArray, Point, Pose, Quaternion, RegionOfInterest, Time, Vector3, cone_class,
    marker_type, ranging,
};

/// The vehicle frame's id in ROS (REP-105's `base_link`).
pub const VEHICLE_FRAME_ID: &str = "base_link";

fn ros_header(header: &pb::Header, frame_id: &str) -> Header {
    Header {
        stamp: Time::from_ns(header.acquisition_time_ns),
        frame_id: frame_id.to_owned(),
    }
}

/// The cones of one frame as a `ConeArray`; each cone's keypoints from `keypoints` (the same
/// frame's keypoints message, matched by the detection's box), none when absent.
pub fn cone_array(
    header: &pb::Header,
    cones: &[LocatedCone],
    keypoints: &[ConeKeypoints],
) -> ConeArray {
    let cones = cones
        .iter()
        .map(|cone| {
            let d = &cone.detection;
            let keypoints = keypoints
                .iter()
                .find(|k| k.detection.box_px == d.box_px && k.detection.class == d.class)
                .map(|k| {
                    k.observation
                        .keypoints_px
                        .iter()
                        .zip(k.observation.weights.iter())
                        .map(|(p, w)| Keypoint {
                            u_px: p.x,
                            v_px: p.y,
                            confidence: w.clamp(0.0, 1.0) as f32,
                        })
                        .collect()
                })
                .unwrap_or_default();
            let p = cone.position_in_vehicle;
            let c = cone.estimate.position_in_camera;
            let v = cone.covariance_in_vehicle_m2;
            Cone {
                cone_class: match d.class {
                    ConeClass::Blue => cone_class::BLUE,
                    ConeClass::Yellow => cone_class::YELLOW,
                    ConeClass::Orange => cone_class::ORANGE,
                    ConeClass::LargeOrange => cone_class::LARGE_ORANGE,
                },
                score: d.score,
                position: Point {
                    x: p.x,
                    y: p.y,
                    z: p.z,
                },
                covariance: std::array::from_fn(|i| v[(i / 3, i % 3)]),
                position_in_camera: Point {
                    x: c.x,
                    y: c.y,
                    z: c.z,
                },
                range_m: cone.estimate.range_m(),
                ranging: match cone.ranging {
                    conesight_core::pnp::Ranging::Keypoints => ranging::KEYPOINTS,
                    conesight_core::pnp::Ranging::KeypointsAndBox => ranging::KEYPOINTS_AND_BOX,
                    conesight_core::pnp::Ranging::Box => ranging::BOX,
                    conesight_core::pnp::Ranging::KeypointsBoxRefused => {
                        ranging::KEYPOINTS_BOX_REFUSED
                    }
                },
                reprojection_rms_px: cone.estimate.reprojection_rms_px,
                tilt_rad: cone.estimate.tilt_rad,
                keypoints,
                box_x_min_px: d.box_px.x_min_px as f32,
                box_y_min_px: d.box_px.y_min_px as f32,
                box_x_max_px: d.box_px.x_max_px as f32,
                box_y_max_px: d.box_px.y_max_px as f32,
            }
        })
        .collect();
    ConeArray {
        header: ros_header(header, VEHICLE_FRAME_ID),
        camera_frame_id: header.frame_id.clone(),
        frame_sequence: header.frame_sequence,
        cones,
    }
}

/// The cones of one frame as RViz markers in the vehicle frame: a `DELETEALL` of the camera's
/// namespace (the previous frame's cones go), then a cylinder of the cone's size and colour
/// standing on each cone's base (0.5 s lifetime, so markers of a stopped pipeline fade).
pub fn cone_markers(array: &ConeArray, camera: &str) -> MarkerArray {
    let ns = format!("conesight/{camera}");
    let mut markers = vec![Marker {
        header: array.header.clone(),
        ns: ns.clone(),
        action: marker_type::DELETEALL,
        ..Marker::default()
    }];
    for (index, cone) in array.cones.iter().enumerate() {
        // FSG cones: small 228 x 228 x 325 mm, large 285 x 285 x 505 mm.
        let (width, height) = if cone.cone_class == cone_class::LARGE_ORANGE {
            (0.285, 0.505)
        } else {
            (0.228, 0.325)
        };
        let (r, g, b) = match cone.cone_class {
            cone_class::BLUE => (0.1, 0.3, 1.0),
            cone_class::YELLOW => (1.0, 0.9, 0.1),
            cone_class::LARGE_ORANGE => (1.0, 0.35, 0.0),
            _ => (1.0, 0.55, 0.0),
        };
        markers.push(Marker {
            header: array.header.clone(),
            ns: ns.clone(),
            id: i32::try_from(index).unwrap_or(i32::MAX),
            r#type: marker_type::CYLINDER,
            action: marker_type::ADD,
            pose: Pose {
                position: Point {
                    x: cone.position.x,
                    y: cone.position.y,
                    z: cone.position.z + height / 2.0,
                },
                orientation: Quaternion {
                    w: 1.0,
                    ..Quaternion::default()
                },
            },
            scale: Vector3 {
                x: width,
                y: width,
                z: height,
            },
            color: ColorRgba { r, g, b, a: 0.9 },
            lifetime: Duration {
                sec: 0,
                nanosec: 500_000_000,
            },
            ..Marker::default()
        });
    }
    MarkerArray { markers }
}

/// A calibration as `sensor_msgs/CameraInfo` (no rectification: `r` identity, `p` = `[K|0]`).
pub fn camera_info(header: &pb::Header, camera: &Camera) -> CameraInfo {
    let d = &camera.distortion;
    let coefficients = match d.model {
        DistortionModel::PlumbBob => vec![d.k1, d.k2, d.p1, d.p2, d.k3],
        DistortionModel::RationalPolynomial => {
            vec![d.k1, d.k2, d.p1, d.p2, d.k3, d.k4, d.k5, d.k6]
        }
        DistortionModel::Equidistant => vec![d.k1, d.k2, d.k3, d.k4],
    };
    let (fx, fy, cx, cy) = (camera.fx_px, camera.fy_px, camera.cx_px, camera.cy_px);
    CameraInfo {
        header: ros_header(header, &header.frame_id),
        height: camera.height_px,
        width: camera.width_px,
        distortion_model: d.model.ros_name().to_owned(),
        d: coefficients,
        k: [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
        r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
        binning_x: 0,
        binning_y: 0,
        roi: RegionOfInterest::default(),
    }
}

/// A `sensor_msgs/CameraInfo` as conesight's camera model. Refused: another distortion model
/// than plumb_bob, rational_polynomial and equidistant, too few coefficients for it, binning
/// or a region of interest (the intrinsics would not be of the full image).
pub fn camera_from_ros(info: &CameraInfo) -> Result<Camera, Ros2Error> {
    let bad = |reason: String| Ros2Error::Invalid {
        type_name: "sensor_msgs/msg/CameraInfo",
        reason,
    };
    let model = match info.distortion_model.as_str() {
        "plumb_bob" | "" => DistortionModel::PlumbBob,
        "rational_polynomial" => DistortionModel::RationalPolynomial,
        "equidistant" => DistortionModel::Equidistant,
        other => {
            return Err(bad(format!(
                "distortion_model {other:?} is not plumb_bob, rational_polynomial or equidistant"
            )));
        }
    };
    if info.binning_x > 1 || info.binning_y > 1 || info.roi.width > 0 || info.roi.height > 0 {
        return Err(bad(
            "binning or a region of interest: give the full image's calibration".to_owned(),
        ));
    }
    let distortion = if info.d.is_empty() {
        Distortion::NONE
    } else {
        Distortion::from_coefficients(model, &info.d).ok_or_else(|| {
            bad(format!(
                "{} distortion coefficients do not fit {} (it takes {})",
                info.d.len(),
                model.ros_name(),
                model.coefficient_count()
            ))
        })?
    };
    let camera = Camera {
        width_px: info.width,
        height_px: info.height,
        fx_px: info.k[0],
        fy_px: info.k[4],
        cx_px: info.k[2],
        cy_px: info.k[5],
        distortion,
    };
    // The plausibility bounds every camera_info passes on the bus (field of view, principal
    // point, distortion).
    conesight_core::bounds::check_camera(&camera).map_err(|e| bad(e.to_string()))?;
    Ok(camera)
}

/// A frame as ROS 2 publishes it: raw frames as `sensor_msgs/Image` (`rgb8`, `bgr8`), JPEG
/// frames as `sensor_msgs/CompressedImage` (`jpeg`).
pub enum RosImage {
    /// Raw pixels.
    Raw(Image),
    /// A JPEG file.
    Compressed(CompressedImage),
}

/// `frame` as a ROS 2 image (the pixels copied once).
pub fn ros_image(frame: &pb::ImageFrame) -> Result<RosImage, Ros2Error> {
    let header =
        conesight_proto::require_header(&frame.header).map_err(|e| Ros2Error::Invalid {
            type_name: "conesight.v1.ImageFrame",
            reason: e.to_string(),
        })?;
    let ros_header = ros_header(header, &header.frame_id);
    let encoding = frame.validate().map_err(|e| Ros2Error::Invalid {
        type_name: "conesight.v1.ImageFrame",
        reason: e.to_string(),
    })?;
    Ok(match encoding {
        pb::ImageEncoding::Jpeg => RosImage::Compressed(CompressedImage {
            header: ros_header,
            format: "jpeg".to_owned(),
            data: frame.data.to_vec(),
        }),
        raw => RosImage::Raw(Image {
            header: ros_header,
            height: frame.height_px,
            width: frame.width_px,
            encoding: if raw == pb::ImageEncoding::Bgr8 {
                "bgr8"
            } else {
                "rgb8"
            }
            .to_owned(),
            is_bigendian: 0,
            step: frame.width_px * 3,
            data: frame.data.to_vec(),
        }),
    })
}

/// Pixel encodings of `sensor_msgs/Image` that conesight reads.
pub const IMAGE_ENCODINGS: &str =
    "rgb8, bgr8, rgba8, bgra8, mono8, bayer_rggb8, bayer_bggr8, bayer_gbrg8, bayer_grbg8";

/// A `sensor_msgs/Image` as RGB pixels. Rows of `step` bytes (padding dropped); `mono8` is
/// grey, `bayer_*8` is demosaiced by bilinear interpolation, alpha is dropped.
pub fn rgb_from_image(image: &Image) -> Result<RgbImage, Ros2Error> {
    let bad = |reason: String| Ros2Error::Invalid {
        type_name: "sensor_msgs/msg/Image",
        reason,
    };
    let (w, h) = (image.width as usize, image.height as usize);
    if w == 0 || h == 0 || w > 16_384 || h > 16_384 {
        return Err(bad(format!("{w}x{h} pixels: each side must be 1..=16384")));
    }
    let channels = match image.encoding.as_str() {
        "rgb8" | "bgr8" => 3,
        "rgba8" | "bgra8" => 4,
        "mono8" | "bayer_rggb8" | "bayer_bggr8" | "bayer_gbrg8" | "bayer_grbg8" => 1,
        other => {
            return Err(bad(format!(
                "encoding {other:?} is not one conesight reads ({IMAGE_ENCODINGS})"
            )));
        }
    };
    let step = image.step as usize;
    if step < w * channels {
        return Err(bad(format!(
            "step {step} bytes is less than width {w} x {channels} bytes per pixel"
        )));
    }
    if image.data.len() < step * (h - 1) + w * channels {
        return Err(bad(format!(
            "{} bytes of data; {h} rows of step {step} need {}",
            image.data.len(),
            step * h
        )));
    }
    let row = |y: usize| &image.data[y * step..y * step + w * channels];
    let mut rgb = RgbImage::new(image.width, image.height);
    let out: &mut [u8] = &mut rgb;
    match image.encoding.as_str() {
        "rgb8" | "rgba8" | "bgr8" | "bgra8" => {
            let swap = image.encoding.starts_with("bgr");
            for y in 0..h {
                for (x, px) in row(y).chunks_exact(channels).enumerate() {
                    let o = (y * w + x) * 3;
                    let (r, b) = if swap { (px[2], px[0]) } else { (px[0], px[2]) };
                    out[o..o + 3].copy_from_slice(&[r, px[1], b]);
                }
            }
        }
        "mono8" => {
            for y in 0..h {
                for (x, v) in row(y).iter().enumerate() {
                    let o = (y * w + x) * 3;
                    out[o..o + 3].copy_from_slice(&[*v, *v, *v]);
                }
            }
        }
        pattern => demosaic(pattern, w, h, &row, out),
    }
    Ok(rgb)
}

/// Bilinear demosaicing of a 2x2 Bayer `pattern` (`bayer_rggb8`, ...).
fn demosaic<'a>(
    pattern: &str,
    w: usize,
    h: usize,
    row: &dyn Fn(usize) -> &'a [u8],
    out: &mut [u8],
) {
    // The colour (0 red, 1 green, 2 blue) of each position of the 2x2 tile.
    let tile: [usize; 4] = match pattern {
        "bayer_rggb8" => [0, 1, 1, 2],
        "bayer_bggr8" => [2, 1, 1, 0],
        "bayer_gbrg8" => [1, 2, 0, 1],
        _ => [1, 0, 2, 1],
    };
    let colour = |x: usize, y: usize| tile[(y % 2) * 2 + x % 2];
    for y in 0..h {
        for x in 0..w {
            let mut sum = [0_u32; 3];
            let mut count = [0_u32; 3];
            for dy in -1_i64..=1 {
                for dx in -1_i64..=1 {
                    let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                    if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                        continue;
                    }
                    let (nx, ny) = (nx as usize, ny as usize);
                    let c = colour(nx, ny);
                    sum[c] += u32::from(row(ny)[nx]);
                    count[c] += 1;
                }
            }
            let o = (y * w + x) * 3;
            for c in 0..3 {
                out[o + c] = if c == colour(x, y) {
                    row(y)[x]
                } else {
                    sum[c].checked_div(count[c]).unwrap_or(0) as u8
                };
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(encoding: &str, width: u32, height: u32, step: u32, data: Vec<u8>) -> Image {
        Image {
            header: Header::default(),
            height,
            width,
            encoding: encoding.into(),
            is_bigendian: 0,
            step,
            data,
        }
    }

    #[test]
    fn rows_with_padding_bgr_and_mono_become_rgb() {
        // 2x2 bgr8 with 2 bytes of padding per row.
        let bgr = image(
            "bgr8",
            2,
            2,
            8,
            vec![1, 2, 3, 4, 5, 6, 0, 0, 7, 8, 9, 10, 11, 12, 0, 0],
        );
        let rgb = rgb_from_image(&bgr).unwrap();
        assert_eq!(rgb.get_pixel(0, 0).0, [3, 2, 1]);
        assert_eq!(rgb.get_pixel(1, 1).0, [12, 11, 10]);
        let mono = rgb_from_image(&image("mono8", 2, 1, 2, vec![9, 200])).unwrap();
        assert_eq!(mono.get_pixel(1, 0).0, [200, 200, 200]);
    }

    #[test]
    fn a_uniform_bayer_image_demosaics_to_its_colour() {
        // An RGGB sensor seeing (200, 100, 50) everywhere.
        let (w, h) = (6_u32, 4_u32);
        let data: Vec<u8> = (0..h)
            .flat_map(|y| {
                (0..w).map(move |x| match (y % 2, x % 2) {
                    (0, 0) => 200,
                    (1, 1) => 50,
                    _ => 100,
                })
            })
            .collect();
        let rgb = rgb_from_image(&image("bayer_rggb8", w, h, w, data)).unwrap();
        for px in rgb.pixels() {
            assert_eq!(px.0, [200, 100, 50]);
        }
    }

    #[test]
    fn bad_images_are_named_errors() {
        for (img, says) in [
            (
                image("yuv422", 2, 2, 4, vec![0; 8]),
                "not one conesight reads",
            ),
            (
                image("rgb8", 2, 2, 5, vec![0; 10]),
                "step 5 bytes is less than",
            ),
            (image("rgb8", 2, 2, 6, vec![0; 7]), "7 bytes of data"),
            (image("mono8", 0, 2, 0, Vec::new()), "each side"),
        ] {
            let error = rgb_from_image(&img).unwrap_err().to_string();
            assert!(error.contains(says), "{error}");
        }
    }

    #[test]
    fn camera_info_round_trips_and_implausible_ones_are_refused() {
        let camera = Camera::paper_default();
        let header = pb::Header::new("front", 3, 1_700_000_000_000_000_000, "front_optical");
        let info = camera_info(&header, &camera);
        assert_eq!(info.header.frame_id, "front_optical");
        let back = camera_from_ros(&info).unwrap();
        assert_eq!(back, camera);
        let mut tiny = info.clone();
        tiny.k[0] = 1.0;
        tiny.k[4] = 1.0;
        assert!(camera_from_ros(&tiny).is_err());
        let mut unknown = info;
        unknown.distortion_model = "fisheye62".into();
        assert!(
            camera_from_ros(&unknown)
                .unwrap_err()
                .to_string()
                .contains("fisheye62")
        );
    }
}
