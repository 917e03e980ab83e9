//! # conesight-onnx
//!
//! Finds the ONNX Runtime shared library, loads it once through `ort` (feature `load-dynamic`)
//! and runs ONNX models on `f32` tensors, with errors that say which file is missing and which
//! command installs it.
//!
//! Modules:
//! - [`runtime`]: [`runtime::locate_library`] (search order) and [`runtime::environment`] (load once).
//! - [`model`]: [`model::OnnxModel`], a session with named `f32` inputs and outputs.
//! - [`provider`]: [`provider::ExecutionProvider`] (`cpu`, `cuda`, `tensorrt`), checked
//!   against the loaded library.
//!
//! Entry point: `OnnxModel::load(path, &ModelOptions::default())`.

pub mod error;
pub mod model;
pub mod provider;
pub mod runtime;

pub use error::OnnxError;
pub use model::{ModelOptions, OnnxModel, TensorF32};
pub use provider::{ExecutionProvider, PROVIDER_FLAG};
pub use runtime::{ORT_LIBRARY_FILE, checkout_roots, environment, locate_library};
