//! Tracing set-up, once per process, from `RUST_LOG`.

use tracing_subscriber::EnvFilter;

/// Filter used when `RUST_LOG` is unset or invalid: our crates at info, ONNX Runtime and
/// Zenoh only from warn (their info lines drown the services' own).
pub(crate) const DEFAULT_LOG_FILTER: &str =
    "info,ort=warn,zenoh=warn,zenoh_transport=warn,zenoh_link_tcp=warn,zenoh_shm=warn";

/// Installs a formatting subscriber filtered by `RUST_LOG` (default: our crates at info, ort and zenoh at warn).
/// A second call does nothing (tests may call it from many places).
pub fn init_tracing() {
    let filter =
        EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(DEFAULT_LOG_FILTER));
    // Err only when a subscriber is already installed, which is fine.
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_target(true)
        .try_init();
}
