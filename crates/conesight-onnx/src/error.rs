//! Errors of the ONNX layer.

use std::path::PathBuf;

/// The command that installs ONNX Runtime and the Python tools into `build/`.
pub const INSTALL_HINT: &str = "run `make setup` (scripts/setup.sh) in the conesight checkout, \
or set ORT_DYLIB_PATH to a libonnxruntime.so 1.31.x";

/// Something went wrong loading ONNX Runtime, a model, or running it.
#[derive(Debug, thiserror::Error)]
pub enum OnnxError {
    /// No ONNX Runtime shared library was found in any searched place.
    #[error("ONNX Runtime library `{file}` not found (looked in: {searched}); {hint}")]
    LibraryNotFound {
        /// The file name looked for.
        file: &'static str,
        /// The places searched, in order.
        searched: String,
        /// How to install it.
        hint: &'static str,
    },
    /// The library file exists but could not be loaded.
    #[error("cannot load ONNX Runtime from {path}: {message}; {hint}")]
    LibraryLoad {
        /// The library path.
        path: PathBuf,
        /// The loader's message.
        message: String,
        /// How to install a working one.
        hint: &'static str,
    },
    /// The execution provider asked for is not in the loaded ONNX Runtime build.
    #[error(
        "execution provider `{provider}` ({ort_name}) asked for by {flag} is not in the \
ONNX Runtime library loaded from {library}; {hint}"
    )]
    ProviderUnavailable {
        /// The flag's value (`cuda`, `tensorrt`).
        provider: &'static str,
        /// ONNX Runtime's name of it.
        ort_name: &'static str,
        /// The library path.
        library: String,
        /// The flag and variable that chose it.
        flag: &'static str,
        /// Which build to install.
        hint: &'static str,
    },
    /// The model file does not exist.
    #[error("model file {path} not found; {hint}")]
    ModelNotFound {
        /// The model path.
        path: PathBuf,
        /// What to do.
        hint: &'static str,
    },
    /// ONNX Runtime rejected the model file.
    #[error("cannot load model {path}: {message}")]
    ModelLoad {
        /// The model path.
        path: PathBuf,
        /// ONNX Runtime's message.
        message: String,
    },
    /// An input tensor does not fit the model.
    #[error("model {model}: input `{input}` {problem}")]
    BadInput {
        /// The model's name (file stem).
        model: String,
        /// The input name.
        input: String,
        /// What is wrong.
        problem: String,
    },
    /// Inference or output extraction failed.
    #[error("model {model}: inference failed: {message}")]
    Run {
        /// The model's name (file stem).
        model: String,
        /// ONNX Runtime's message.
        message: String,
    },
}
