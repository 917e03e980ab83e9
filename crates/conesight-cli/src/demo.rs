//! The geometry demo: cones on a curved Formula Student track, 2-30 m ahead of the paper's
//! camera; their exact silhouette keypoints with Gaussian noise go through the cone PnP solver.

use std::path::PathBuf;

use anyhow::Context;
use conesight_core::cone::{ConeClass, ConeModel, silhouette_keypoints};
use conesight_core::pnp::{ConeObservation, ConePnpParams, solve_cone};
use conesight_core::{Camera, Extrinsics};
use nalgebra::{Isometry3, Point2, Point3, Translation3, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use crate::bev::{BevCone, write_bev_png};

/// Arguments of `conesight demo`.
#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// Standard deviation of the keypoint noise, pixels.
    #[arg(long, default_value_t = 0.5)]
    noise_px: f64,
    /// Seed of the noise.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Radius of the track's left-hand curve, metres (large = straight).
    #[arg(long, default_value_t = 60.0)]
    curve_radius_m: f64,
    /// Output folder for the PNGs.
    #[arg(long, default_value = "out/demo")]
    out: PathBuf,
    /// Only the geometry part (no rendered frame, no keypoint network).
    #[arg(long)]
    skip_frame: bool,
}

/// Track half width, metres (FS rules: at least 3 m wide).
const TRACK_HALF_WIDTH_M: f64 = 1.75;
/// Spacing of cones along the track, metres (FS rules: at most 5 m).
const CONE_SPACING_M: f64 = 4.5;
/// Farthest cone placed, metres along the track.
const MAX_ALONG_M: f64 = 30.0;

/// One cone of the demo track, in the vehicle frame.
struct TrackCone {
    class: ConeClass,
    position_in_vehicle: Point3<f64>,
}

/// A left-hand arc of radius `radius_m` starting straight ahead: blue on the left, yellow on
/// the right, two large orange cones at the start line.
fn track(radius_m: f64) -> Vec<TrackCone> {
    let mut cones = Vec::new();
    let mut along_m = 5.5;
    while along_m <= MAX_ALONG_M {
        let heading = along_m / radius_m;
        let centre = Point3::new(
            radius_m * heading.sin(),
            radius_m * (1.0 - heading.cos()),
            0.0,
        );
        let left = Vector3::new(-heading.sin(), heading.cos(), 0.0);
        let is_start = along_m < 6.0;
        for (side, class) in [(1.0, ConeClass::Blue), (-1.0, ConeClass::Yellow)] {
            let class = if is_start {
                ConeClass::LargeOrange
            } else {
                class
            };
            cones.push(TrackCone {
                class,
                position_in_vehicle: centre + left * (side * TRACK_HALF_WIDTH_M),
            });
        }
        along_m += CONE_SPACING_M;
    }
    cones
}

/// Runs the demo.
pub fn run(args: &DemoArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.noise_px.is_finite() && args.noise_px >= 0.0,
        "--noise-px must be a finite number >= 0, got {}",
        args.noise_px
    );
    let camera = Camera::paper_default();
    let extrinsics = Extrinsics::paper_default();
    let camera_from_vehicle = extrinsics.camera_from_vehicle();
    let params = ConePnpParams::for_keypoint_sigma(args.noise_px.max(0.1))
        .with_extrinsics(&extrinsics, false);
    let noise = Normal::new(0.0, args.noise_px).context("noise distribution")?;
    let mut rng = ChaCha8Rng::seed_from_u64(args.seed);

    println!(
        "conesight demo: paper camera {}x{} f={:.1} px, 1.0 m high; keypoint noise {} px (seed {})",
        camera.width_px, camera.height_px, camera.fx_px, args.noise_px, args.seed
    );
    println!(
        "{:>3}  {:<12} {:>8} {:>8} {:>8} {:>9} {:>8}",
        "#", "class", "range_m", "est_m", "err_m", "err_%", "1sig_m"
    );
    let mut plotted = Vec::new();
    let mut errors_pct = Vec::new();
    for (index, cone) in track(args.curve_radius_m).iter().enumerate() {
        let model = ConeModel::for_class(cone.class);
        let camera_from_cone = camera_from_vehicle
            * Isometry3::from_parts(
                Translation3::from(cone.position_in_vehicle.coords),
                nalgebra::UnitQuaternion::identity(),
            );
        let Ok(exact) = silhouette_keypoints(&camera, &model, &camera_from_cone) else {
            continue;
        };
        if !exact.iter().all(|p| camera.contains(p)) {
            continue;
        }
        let noisy: [Point2<f64>; 7] =
            exact.map(|p| Point2::new(p.x + noise.sample(&mut rng), p.y + noise.sample(&mut rng)));
        let truth_in_camera = camera_from_vehicle * cone.position_in_vehicle;
        let estimate = solve_cone(&camera, &model, &ConeObservation::new(noisy), &params)
            .with_context(|| format!("cone {index} at {:.1} m", truth_in_camera.coords.norm()))?;
        let range_m = truth_in_camera.coords.norm();
        let error_m = (estimate.position_in_camera - truth_in_camera).norm();
        let sigma_m = estimate.covariance_m2.trace().sqrt();
        errors_pct.push(100.0 * error_m / range_m);
        println!(
            "{:>3}  {:<12} {:>8.2} {:>8.2} {:>8.3} {:>8.2}% {:>8.3}",
            index,
            cone.class.as_str(),
            range_m,
            estimate.range_m(),
            error_m,
            100.0 * error_m / range_m,
            sigma_m
        );
        let vehicle_from_camera = extrinsics.vehicle_from_camera;
        plotted.push(BevCone {
            class: cone.class,
            truth_in_vehicle: Some(cone.position_in_vehicle),
            estimate_in_vehicle: vehicle_from_camera * estimate.position_in_camera,
            covariance_in_vehicle: vehicle_from_camera.rotation.to_rotation_matrix().matrix()
                * estimate.covariance_m2
                * vehicle_from_camera
                    .rotation
                    .to_rotation_matrix()
                    .matrix()
                    .transpose(),
        });
    }
    anyhow::ensure!(!plotted.is_empty(), "no cone of the demo track is in view");
    errors_pct.sort_by(f64::total_cmp);
    let median = errors_pct[errors_pct.len() / 2];
    println!(
        "{} cones solved; median position error {:.2}% of range, worst {:.2}%",
        plotted.len(),
        median,
        errors_pct[errors_pct.len() - 1]
    );
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create output folder {}", args.out.display()))?;
    let png = args.out.join("bev.png");
    write_bev_png(&png, &plotted, Some((camera.width_px, camera.fx_px)), 0)?;
    println!(
        "bird's-eye view: {} (filled discs: truth in cone colour; black crosses: estimates; grey ellipses: 3-sigma)",
        png.display()
    );
    if args.skip_frame {
        return Ok(());
    }
    let mut frame_errors = crate::demo_frame::run(args.seed, &args.out)?;
    if !frame_errors.is_empty() {
        frame_errors.sort_by(f64::total_cmp);
        println!(
            "{} cones solved from network keypoints; median position error {:.2}% of range, worst {:.2}%",
            frame_errors.len(),
            100.0 * frame_errors[frame_errors.len() / 2],
            100.0 * frame_errors[frame_errors.len() - 1]
        );
    }
    Ok(())
}
