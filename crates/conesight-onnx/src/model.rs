//! An ONNX model session with `f32` tensors in and out.

use std::path::{Path, PathBuf};

use ort::session::Session;
use ort::session::builder::GraphOptimizationLevel;
use ort::value::Tensor;

use crate::error::OnnxError;
use crate::provider::ExecutionProvider;
use crate::runtime::environment;

/// How to open a model.
#[derive(Debug, Clone, Default)]
pub struct ModelOptions {
    /// ONNX Runtime library to use instead of the search (see [`crate::locate_library`]).
    pub library: Option<PathBuf>,
    /// Intra-op threads; `None` lets ONNX Runtime decide (all cores).
    pub intra_threads: Option<usize>,
    /// Whether idle intra-op threads spin (busy-wait) for the next call. Off by default (ONNX
    /// Runtime's own default is on): on a 2-core host one model's spinning threads take the
    /// core another model or service is computing on, and even a lone back-to-back loop was no
    /// faster with them (models/detector.md, Speed).
    pub allow_spinning: bool,
    /// Where the models run (`--execution-provider`); CPU by default.
    pub execution_provider: ExecutionProvider,
}

/// A dense `f32` tensor: shape and row-major data.
#[derive(Debug, Clone, PartialEq)]
pub struct TensorF32 {
    /// Dimensions.
    pub shape: Vec<usize>,
    /// Row-major values, `shape.iter().product()` of them.
    pub data: Vec<f32>,
}

/// A loaded ONNX model.
pub struct OnnxModel {
    name: String,
    path: PathBuf,
    session: Session,
}

impl std::fmt::Debug for OnnxModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OnnxModel")
            .field("path", &self.path)
            .finish_non_exhaustive()
    }
}

impl OnnxModel {
    /// Loads ONNX Runtime if needed, then the model at `path`.
    pub fn load(path: &Path, options: &ModelOptions) -> Result<Self, OnnxError> {
        if !path.is_file() {
            return Err(OnnxError::ModelNotFound {
                path: path.to_path_buf(),
                hint: "pass the right --model path; shipped models live in the checkout's models/ folder",
            });
        }
        let env = environment(options.library.as_deref())?;
        let load_error = |e: ort::Error| OnnxError::ModelLoad {
            path: path.to_path_buf(),
            message: e.to_string(),
        };
        let mut builder = Session::builder(env)
            .map_err(load_error)?
            .with_optimization_level(GraphOptimizationLevel::Level3)
            .map_err(|e| load_error(e.into()))?;
        if let Some(threads) = options.intra_threads {
            builder = builder
                .with_intra_threads(threads)
                .map_err(|e| load_error(e.into()))?;
        }
        builder = builder
            .with_intra_op_spinning(options.allow_spinning)
            .map_err(|e| load_error(e.into()))?
            .with_inter_op_spinning(options.allow_spinning)
            .map_err(|e| load_error(e.into()))?;
        if options.execution_provider != ExecutionProvider::Cpu {
            options.execution_provider.check_available()?;
            builder = builder
                .with_execution_providers(options.execution_provider.dispatch())
                .map_err(|e| OnnxError::ModelLoad {
                    path: path.to_path_buf(),
                    message: format!(
                        "execution provider `{}` is in the library but failed to start \
                         (its CUDA/TensorRT libraries?): {e}",
                        options.execution_provider
                    ),
                })?;
        }
        let session = builder.commit_from_file(path).map_err(load_error)?;
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        Ok(Self {
            name,
            path: path.to_path_buf(),
            session,
        })
    }

    /// The model's input names, in graph order.
    pub fn input_names(&self) -> Vec<String> {
        self.session
            .inputs()
            .iter()
            .map(|i| i.name().to_owned())
            .collect()
    }

    /// The model's output names, in graph order.
    pub fn output_names(&self) -> Vec<String> {
        self.session
            .outputs()
            .iter()
            .map(|o| o.name().to_owned())
            .collect()
    }

    /// The model's custom metadata (`metadata_props`: key, value), sorted by key; empty when
    /// the model has none or ONNX Runtime cannot read it. Ultralytics exports write `names`,
    /// `imgsz`, `stride`, `task` and `end2end` there; conesight's detector writes its layout.
    pub fn metadata(&self) -> Vec<(String, String)> {
        let Ok(metadata) = self.session.metadata() else {
            return Vec::new();
        };
        let mut keys = metadata.custom_keys().unwrap_or_default();
        keys.sort();
        keys.into_iter()
            .filter_map(|k| metadata.custom(&k).map(|v| (k, v)))
            .collect()
    }

    /// The file the model was loaded from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Runs the model on one `f32` input per graph input (in graph order) and returns every
    /// output as `f32`, in graph order.
    pub fn run(&mut self, inputs: Vec<TensorF32>) -> Result<Vec<TensorF32>, OnnxError> {
        let names = self.input_names();
        if inputs.len() != names.len() {
            return Err(OnnxError::BadInput {
                model: self.name.clone(),
                input: names.join(","),
                problem: format!("expects {} inputs, got {}", names.len(), inputs.len()),
            });
        }
        let mut values = Vec::with_capacity(inputs.len());
        for (name, input) in names.iter().zip(inputs) {
            let expected: usize = input.shape.iter().product();
            if expected != input.data.len() || input.data.iter().any(|v| !v.is_finite()) {
                return Err(OnnxError::BadInput {
                    model: self.name.clone(),
                    input: name.clone(),
                    problem: if expected != input.data.len() {
                        format!(
                            "shape {:?} needs {expected} values, got {}",
                            input.shape,
                            input.data.len()
                        )
                    } else {
                        "contains NaN or infinity".to_owned()
                    },
                });
            }
            let tensor = Tensor::from_array((input.shape.clone(), input.data)).map_err(|e| {
                OnnxError::BadInput {
                    model: self.name.clone(),
                    input: name.clone(),
                    problem: e.to_string(),
                }
            })?;
            values.push((name.clone(), tensor));
        }
        let run_error = |e: ort::Error| OnnxError::Run {
            model: self.name.clone(),
            message: e.to_string(),
        };
        let output_names = self.output_names();
        let outputs = self.session.run(values).map_err(run_error)?;
        let mut result = Vec::with_capacity(output_names.len());
        for name in &output_names {
            let value = outputs.get(name).ok_or_else(|| OnnxError::Run {
                model: self.name.clone(),
                message: format!("output `{name}` missing"),
            })?;
            let (shape, data) = value
                .try_extract_tensor::<f32>()
                .map_err(|e| OnnxError::Run {
                    model: self.name.clone(),
                    message: format!("output `{name}`: {e}"),
                })?;
            result.push(TensorF32 {
                shape: shape
                    .iter()
                    .map(|d| usize::try_from(*d).unwrap_or(0))
                    .collect(),
                data: data.to_vec(),
            });
        }
        Ok(result)
    }
}
