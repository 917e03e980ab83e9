//! Which ONNX Runtime execution provider runs the models: CPU (the default, what the PyPI wheel
//! has), or NVIDIA's CUDA or TensorRT when the loaded library was built with them (a Jetson's
//! JetPack build, deploy/README.md "Jetson").
//!
//! A provider that was asked for and is missing is an error naming the flag and the build to
//! install ([`crate::OnnxError::ProviderUnavailable`]), never a silent fall-back to the CPU. Within
//! a GPU session, ONNX Runtime still places the few operators the provider lacks on the CPU
//! (its normal graph partitioning); TensorRT is registered with CUDA behind it for those.

use std::fmt;
use std::str::FromStr;

use ort::ep::{self, ExecutionProvider as _, ExecutionProviderDispatch};

use crate::error::OnnxError;

/// The flag and variable that choose the provider, for messages.
pub const PROVIDER_FLAG: &str = "--execution-provider (CONESIGHT_EXECUTION_PROVIDER)";

/// An execution provider conesight can run its models on.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum ExecutionProvider {
    /// ONNX Runtime's CPU provider (always there).
    #[default]
    Cpu,
    /// `CUDAExecutionProvider`.
    Cuda,
    /// `TensorrtExecutionProvider`, with CUDA for the operators TensorRT does not take.
    TensorRt,
}

impl ExecutionProvider {
    /// Every value, in the order `--help` lists them.
    pub const ALL: [Self; 3] = [Self::Cpu, Self::Cuda, Self::TensorRt];

    /// The flag's spelling: `cpu`, `cuda`, `tensorrt`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Cpu => "cpu",
            Self::Cuda => "cuda",
            Self::TensorRt => "tensorrt",
        }
    }

    /// ONNX Runtime's name of the provider.
    pub fn ort_name(self) -> &'static str {
        match self {
            Self::Cpu => ep::CPU::NAME,
            Self::Cuda => ep::CUDA::NAME,
            Self::TensorRt => ep::TensorRT::NAME,
        }
    }

    /// Whether the loaded ONNX Runtime library was built with this provider (needs the
    /// library loaded: [`crate::environment`]).
    pub fn is_available(self) -> Result<bool, ort::Error> {
        match self {
            Self::Cpu => Ok(true),
            Self::Cuda => ep::CUDA::is_available(),
            Self::TensorRt => Ok(ep::TensorRT::is_available()? && ep::CUDA::is_available()?),
        }
    }

    /// The providers to register on a session, each failing the session when it cannot be
    /// registered (so a missing CUDA library is an error, not a CPU session). Empty for CPU.
    pub(crate) fn dispatch(self) -> Vec<ExecutionProviderDispatch> {
        match self {
            Self::Cpu => Vec::new(),
            Self::Cuda => vec![ep::CUDA::default().build().error_on_failure()],
            Self::TensorRt => vec![
                ep::TensorRT::default().build().error_on_failure(),
                ep::CUDA::default().build().error_on_failure(),
            ],
        }
    }

    /// `Ok` when the loaded library has this provider, else the error that says what to do.
    pub fn check_available(self) -> Result<(), OnnxError> {
        let library = crate::runtime::loaded_library()
            .map(|p| p.display().to_string())
            .unwrap_or_else(|| "(not loaded)".to_owned());
        match self.is_available() {
            Ok(true) => Ok(()),
            Ok(false) => Err(OnnxError::ProviderUnavailable {
                provider: self.as_str(),
                ort_name: self.ort_name(),
                library,
                flag: PROVIDER_FLAG,
                hint: GPU_BUILD_HINT,
            }),
            Err(e) => Err(OnnxError::LibraryLoad {
                path: library.into(),
                message: format!("cannot list its execution providers: {e}"),
                hint: crate::error::INSTALL_HINT,
            }),
        }
    }
}

/// Which ONNX Runtime to install for the GPU providers.
pub const GPU_BUILD_HINT: &str = "the PyPI wheel onnxruntime (what `make setup` installs) is \
CPU only: on a Jetson use NVIDIA's onnxruntime-gpu 1.31 build for your JetPack (Jetson AI Lab / \
Jetson Zoo wheel, or built from source with --use_cuda --use_tensorrt) and point ORT_DYLIB_PATH \
at its libonnxruntime.so; on x86 the onnxruntime-gpu wheel; or pass --execution-provider cpu";

impl fmt::Display for ExecutionProvider {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A `--execution-provider` value that is none of `cpu`, `cuda`, `tensorrt`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown execution provider `{0}` (one of: cpu, cuda, tensorrt)")]
pub struct UnknownProvider(pub String);

impl FromStr for ExecutionProvider {
    type Err = UnknownProvider;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|p| p.as_str().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| UnknownProvider(s.to_owned()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_every_spelling_and_refuses_others() {
        for p in ExecutionProvider::ALL {
            assert_eq!(p.as_str().parse::<ExecutionProvider>(), Ok(p));
        }
        assert_eq!("CUDA".parse(), Ok(ExecutionProvider::Cuda));
        assert!("rocm".parse::<ExecutionProvider>().is_err());
    }
}
