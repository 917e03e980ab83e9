//! End-to-end proof of the offline ONNX Runtime recipe: the real library from the PyPI wheel,
//! loaded dynamically, runs a real (tiny) ONNX model.

use std::path::{Path, PathBuf};

use conesight_onnx::{ModelOptions, OnnxError, OnnxModel, TensorF32, runtime};

fn tiny_model() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/tiny_affine.onnx")
}

#[test]
fn runs_tiny_model_with_real_onnx_runtime() {
    let mut model = OnnxModel::load(&tiny_model(), &ModelOptions::default())
        .expect("ONNX Runtime installed by `make setup` and the model loads");
    assert_eq!(model.input_names(), vec!["x"]);
    assert_eq!(model.output_names(), vec!["y"]);
    let x = TensorF32 {
        shape: vec![2, 3],
        data: vec![1.0, 2.0, 3.0, -1.0, 0.0, 0.5],
    };
    let outputs = model.run(vec![x]).expect("inference runs");
    // W = [[1, -2], [0.5, 0], [3, 1]], b = [0.25, -1] (scripts/make_tiny_onnx.py).
    let expected = [
        1.0 + 1.0 + 9.0 + 0.25,
        -2.0 + 0.0 + 3.0 - 1.0,
        -1.0 + 0.0 + 1.5 + 0.25,
        2.0 + 0.0 + 0.5 - 1.0,
    ];
    assert_eq!(outputs[0].shape, vec![2, 2]);
    for (got, want) in outputs[0].data.iter().zip(expected) {
        assert!((got - want).abs() < 1e-5, "got {got}, want {want}");
    }
    assert!(runtime::loaded_library().is_some());
}

#[test]
fn wrong_input_size_and_nan_are_errors_not_panics() {
    let mut model = OnnxModel::load(&tiny_model(), &ModelOptions::default()).expect("loads");
    let short = TensorF32 {
        shape: vec![1, 3],
        data: vec![1.0, 2.0],
    };
    let err = model.run(vec![short]).expect_err("size mismatch");
    assert!(err.to_string().contains("needs 3 values, got 2"), "{err}");
    let nan = TensorF32 {
        shape: vec![1, 3],
        data: vec![1.0, f32::NAN, 0.0],
    };
    let err = model.run(vec![nan]).expect_err("NaN rejected");
    assert!(err.to_string().contains("NaN"), "{err}");
    let wrong_rank = TensorF32 {
        shape: vec![3],
        data: vec![1.0, 2.0, 3.0],
    };
    assert!(matches!(
        model.run(vec![wrong_rank]),
        Err(OnnxError::Run { .. } | OnnxError::BadInput { .. })
    ));
}

#[test]
fn missing_library_names_the_file_and_the_install_command() {
    let dir = std::env::temp_dir().join("conesight-no-ort-here");
    let err = runtime::first_existing(vec![dir.join(runtime::ORT_LIBRARY_FILE)])
        .expect_err("nothing there");
    let message = err.to_string();
    assert!(message.contains("libonnxruntime.so.1.31.1"), "{message}");
    assert!(message.contains("make setup"), "{message}");
    assert!(message.contains("conesight-no-ort-here"), "{message}");
}

#[test]
fn missing_model_is_an_error() {
    let err = OnnxModel::load(
        Path::new("models/does-not-exist.onnx"),
        &ModelOptions::default(),
    )
    .expect_err("missing model");
    assert!(matches!(err, OnnxError::ModelNotFound { .. }), "{err}");
    assert!(err.to_string().contains("does-not-exist.onnx"));
}
