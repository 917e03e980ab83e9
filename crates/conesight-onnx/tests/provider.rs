//! `--execution-provider` against the real ONNX Runtime from the PyPI wheel (CPU only): `cpu`
//! runs, `cuda` and `tensorrt` are refused with a message naming the flag and the build to
//! install, and nothing falls back to the CPU silently.

use std::path::{Path, PathBuf};

use conesight_onnx::{ExecutionProvider, ModelOptions, OnnxError, OnnxModel, TensorF32};

fn tiny_model() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/tiny_affine.onnx")
}

fn options(execution_provider: ExecutionProvider) -> ModelOptions {
    ModelOptions {
        execution_provider,
        ..ModelOptions::default()
    }
}

#[test]
fn cpu_runs() {
    let mut model =
        OnnxModel::load(&tiny_model(), &options(ExecutionProvider::Cpu)).expect("loads");
    let x = TensorF32 {
        shape: vec![1, 3],
        data: vec![1.0, 2.0, 3.0],
    };
    assert_eq!(model.run(vec![x]).expect("runs")[0].shape, vec![1, 2]);
    assert_eq!(ExecutionProvider::Cpu.is_available().ok(), Some(true));
}

#[test]
fn gpu_providers_missing_from_the_cpu_wheel_are_clear_errors() {
    for provider in [ExecutionProvider::Cuda, ExecutionProvider::TensorRt] {
        let err = OnnxModel::load(&tiny_model(), &options(provider)).expect_err("CPU-only library");
        assert!(
            matches!(err, OnnxError::ProviderUnavailable { .. }),
            "{provider}: {err}"
        );
        let message = err.to_string();
        for needle in [
            "--execution-provider",
            "CONESIGHT_EXECUTION_PROVIDER",
            provider.ort_name(),
            "onnxruntime-gpu",
            "libonnxruntime.so",
        ] {
            assert!(message.contains(needle), "`{needle}` not in: {message}");
        }
        assert_eq!(provider.is_available().ok(), Some(false));
    }
}
