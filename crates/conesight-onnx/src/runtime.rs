//! Locating and loading the ONNX Runtime shared library, once per process.
//!
//! Search order for [`locate_library`]:
//! 1. an explicit path (a CLI flag),
//! 2. the `ORT_DYLIB_PATH` environment variable,
//! 3. `build/onnxruntime/<file>` under the current directory and each of its parents,
//! 4. `build/onnxruntime/<file>` under the running executable's ancestors (so
//!    `target/release/conesight` finds the checkout's copy from anywhere),
//! 5. `build/onnxruntime/<file>` under this crate's workspace (for tests).

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use crate::error::{INSTALL_HINT, OnnxError};

/// The library file scripts/setup.sh extracts from the `onnxruntime==1.31.1` wheel.
pub const ORT_LIBRARY_FILE: &str = "libonnxruntime.so.1.31.1";

/// Where scripts/setup.sh puts the library, relative to the checkout.
const RELATIVE_LIBRARY_DIR: &str = "build/onnxruntime";

/// Finds the ONNX Runtime library; see the module docs for the search order.
pub fn locate_library(explicit: Option<&Path>) -> Result<PathBuf, OnnxError> {
    let mut candidates: Vec<PathBuf> = Vec::new();
    if let Some(path) = explicit {
        candidates.push(path.to_path_buf());
    }
    if let Some(path) = std::env::var_os("ORT_DYLIB_PATH").filter(|p| !p.is_empty()) {
        candidates.push(PathBuf::from(path));
    }
    for root in checkout_roots() {
        let candidate = root.join(RELATIVE_LIBRARY_DIR).join(ORT_LIBRARY_FILE);
        if !candidates.contains(&candidate) {
            candidates.push(candidate);
        }
    }
    first_existing(candidates)
}

/// Folders that may be the conesight checkout, most specific first: the current directory
/// and its parents, the running executable's ancestors (so `target/release/conesight` finds
/// the checkout from anywhere), and this workspace (for tests). Shipped files (`build/...`,
/// `models/...`) are looked up under each.
pub fn checkout_roots() -> Vec<PathBuf> {
    let mut roots: Vec<PathBuf> = Vec::new();
    if let Ok(cwd) = std::env::current_dir() {
        roots.extend(cwd.ancestors().map(Path::to_path_buf));
    }
    if let Ok(exe) = std::env::current_exe() {
        roots.extend(exe.ancestors().skip(1).map(Path::to_path_buf));
    }
    roots.extend(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .ancestors()
            .map(Path::to_path_buf),
    );
    roots
}

/// The first of `candidates` that is a file, or an error listing all of them.
pub fn first_existing(candidates: Vec<PathBuf>) -> Result<PathBuf, OnnxError> {
    let mut searched = Vec::with_capacity(candidates.len());
    for candidate in candidates {
        if candidate.is_file() {
            return Ok(candidate);
        }
        searched.push(candidate.display().to_string());
    }
    Err(OnnxError::LibraryNotFound {
        file: ORT_LIBRARY_FILE,
        searched: searched.join(", "),
        hint: INSTALL_HINT,
    })
}

/// The process-wide environment, or the message of the first failed attempt to create it.
static ENVIRONMENT: OnceLock<Result<ort::environment::Environment, String>> = OnceLock::new();
/// The library path the environment was loaded from.
static LOADED_FROM: OnceLock<PathBuf> = OnceLock::new();

/// Loads ONNX Runtime (once per process) and returns its environment.
///
/// The first call decides which library is used; later calls with another `explicit` path get
/// the already-loaded one (ONNX Runtime cannot be loaded twice into one process).
pub fn environment(
    explicit: Option<&Path>,
) -> Result<&'static ort::environment::Environment, OnnxError> {
    if let Some(loaded) = ENVIRONMENT.get() {
        return loaded.as_ref().map_err(|message| OnnxError::LibraryLoad {
            path: LOADED_FROM.get().cloned().unwrap_or_default(),
            message: message.clone(),
            hint: INSTALL_HINT,
        });
    }
    let path = locate_library(explicit)?;
    let result = ENVIRONMENT.get_or_init(|| {
        let _ = LOADED_FROM.set(path.clone());
        tracing::debug!(library = %path.display(), "loading ONNX Runtime");
        ort::init_from(&path)
            .map_err(|e| e.to_string())?
            .with_name("conesight")
            .build()
            .map_err(|e| e.to_string())
    });
    result.as_ref().map_err(|message| OnnxError::LibraryLoad {
        path,
        message: message.clone(),
        hint: INSTALL_HINT,
    })
}

/// The library path ONNX Runtime was loaded from, once [`environment`] succeeded.
pub fn loaded_library() -> Option<&'static Path> {
    LOADED_FROM.get().map(PathBuf::as_path)
}
