//! Tracing set-up, once per process, from `RUST_LOG`.

use tracing_subscriber::EnvFilter;

/// Filter used when `RUST_LOG` is unset or invalid.
pub(crate) const DEFAULT_LOG_FILTER: &str = "info";

/// Installs a formatting subscriber filtered by `RUST_LOG` (default `info`).
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
