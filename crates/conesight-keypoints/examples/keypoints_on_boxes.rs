//! Runs the shipped keypoint network on given boxes of one image and prints the keypoints in
//! image pixels as JSON: the Rust half of the Rust-vs-PyTorch parity test
//! (`training/tests/test_rust_parity.py`), also handy for poking at the model by hand.
//!
//! ```text
//! cargo run -p conesight-keypoints --example keypoints_on_boxes -- IMAGE X1,Y1,X2,Y2 [...]
//! ```
//! Box edges are continuous pixels (OpenCV convention: pixel (i, j) spans i +- 0.5).

use std::path::PathBuf;
use std::process::ExitCode;

use conesight_keypoints::{KeypointNet, locate_model};
use conesight_onnx::ModelOptions;
use conesight_vision::PixelBox;

fn parse_box(text: &str) -> Result<PixelBox, String> {
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("box {text:?}: {e}; expected X1,Y1,X2,Y2"))?;
    match values.as_slice() {
        [x1, y1, x2, y2] => Ok(PixelBox {
            x_min_px: *x1,
            y_min_px: *y1,
            x_max_px: *x2,
            y_max_px: *y2,
        }),
        _ => Err(format!("box {text:?}: expected 4 numbers X1,Y1,X2,Y2")),
    }
}

fn run() -> Result<(), String> {
    let mut args = std::env::args().skip(1);
    let image_path = PathBuf::from(
        args.next()
            .ok_or("usage: keypoints_on_boxes IMAGE X1,Y1,X2,Y2 [...]")?,
    );
    let boxes: Vec<PixelBox> = args.map(|a| parse_box(&a)).collect::<Result<_, _>>()?;
    let image = image::open(&image_path)
        .map_err(|e| format!("cannot read image {}: {e}", image_path.display()))?
        .to_rgb8();
    let model = locate_model(None);
    let mut net = KeypointNet::load(&model, &ModelOptions::default())
        .map_err(|e| format!("keypoint model {}: {e}", model.display()))?;
    let predictions = net
        .predict_boxes(&image, &boxes)
        .map_err(|e| format!("inference: {e}"))?;
    let cones: Vec<serde_json::Value> = predictions
        .iter()
        .map(|p| {
            serde_json::json!({
                "keypoints_px": p.keypoints_px.iter().map(|k| [k.x, k.y]).collect::<Vec<_>>(),
                "sigma_px": p.sigma_px,
            })
        })
        .collect();
    println!("{}", serde_json::json!({ "cones": cones }));
    Ok(())
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("keypoints_on_boxes: {message}");
            ExitCode::FAILURE
        }
    }
}
