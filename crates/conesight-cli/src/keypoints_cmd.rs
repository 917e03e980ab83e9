//! `conesight keypoints`: the keypoint network on cone crops (one cone per image, any size),
//! one JSON line each with the 7 keypoints in the crop's own pixels, their confidences in
//! [0, 1] (`conesight_proto::confidence_from_weight`: 0.5 at 1 px of predicted noise) and the
//! predicted noise itself (`sigma_px`).

use std::io::Write;
use std::path::PathBuf;

use conesight_onnx::ModelOptions;
use conesight_pipeline::KeypointStage;
use conesight_pipeline::keypoint_stage::REFERENCE_SIGMA_PX;
use conesight_pipeline::models::locate_keypoint_model;
use conesight_pipeline::source::read_image;
use conesight_proto::confidence_from_weight;
use conesight_vision::PixelBox;
use serde_json::json;

/// Arguments of `conesight keypoints`.
#[derive(Debug, clap::Args)]
pub struct KeypointsArgs {
    /// Keypoint model (default: the checkout's models/keypoints.onnx).
    #[arg(long)]
    model: Option<PathBuf>,
    /// ONNX Runtime library (default: the checkout's build/onnxruntime, or ORT_DYLIB_PATH).
    #[arg(long = "onnxruntime")]
    onnxruntime: Option<PathBuf>,
    /// Where the model runs: cpu, cuda or tensorrt.
    #[arg(
        long = "execution-provider",
        env = "CONESIGHT_EXECUTION_PROVIDER",
        default_value_t
    )]
    execution_provider: conesight_onnx::ExecutionProvider,
    /// Cone crops: the whole image is taken as the cone's box (PNG, JPEG, ...).
    #[arg(required = true)]
    images: Vec<PathBuf>,
}

/// Runs `conesight keypoints`; fails (after every image) when any image failed.
pub fn run(args: &KeypointsArgs) -> anyhow::Result<()> {
    let path = locate_keypoint_model(args.model.as_deref());
    let onnx = ModelOptions {
        library: args.onnxruntime.clone(),
        intra_threads: None,
        allow_spinning: false,
        execution_provider: args.execution_provider,
    };
    let mut stage = KeypointStage::load(&path, &onnx)?;
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    let mut failed = 0_usize;
    for image_path in &args.images {
        let result = read_image(image_path)
            .map_err(anyhow::Error::from)
            .and_then(|image| {
                let whole = PixelBox {
                    x_min_px: -0.5,
                    y_min_px: -0.5,
                    x_max_px: f64::from(image.width()) - 0.5,
                    y_max_px: f64::from(image.height()) - 0.5,
                };
                let mut cones = stage.net_mut().predict_boxes(&image, &[whole])?;
                cones
                    .pop()
                    .ok_or_else(|| anyhow::anyhow!("the network returned no keypoints"))
            });
        let line = match result {
            Ok(cone) => json!({
                "image": image_path.display().to_string(),
                "keypoints_px": cone.keypoints_px.iter().map(|p| [p.x, p.y]).collect::<Vec<_>>(),
                "confidence": cone.weights(REFERENCE_SIGMA_PX).map(confidence_from_weight),
                "sigma_px": cone.sigma_px,
            }),
            Err(error) => {
                failed += 1;
                eprintln!("{}: {error:#}", image_path.display());
                json!({"image": image_path.display().to_string(), "error": format!("{error:#}")})
            }
        };
        writeln!(out, "{line}")?;
    }
    anyhow::ensure!(
        failed == 0,
        "{failed} of {} images failed",
        args.images.len()
    );
    Ok(())
}
