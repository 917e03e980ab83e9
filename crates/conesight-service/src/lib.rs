//! # conesight-service
//!
//! What every conesight service shares, so each `main.rs` stays thin.
//!
//! Modules:
//! - `telemetry`: [`init_tracing`] (stderr) or [`init_tracing_to_file`] from `RUST_LOG`
//!   (default `info`).
//! - `shutdown`: [`shutdown_signal`], resolving on SIGTERM or SIGINT.
//! - [`metrics`]: [`Metrics`], a Prometheus registry with frames received/processed/dropped,
//!   errors by kind, per-stage latency histograms and the queue depth.
//! - [`health`]: [`Readiness`], the shared state behind `/readyz` (model loaded, session up,
//!   last input fresh).
//! - [`http`]: [`router`] (`/livez`, `/readyz`, `/metrics`), [`HttpArgs`] and [`serve`].
//! - [`mod@healthcheck`]: [`healthcheck()`], an HTTP GET of `/readyz` for containers without curl.
//! - [`refusals`]: messages Zenoh refuses over its receive limit, counted from its trace event.
//! - [`errors`]: [`ErrorReporter`], counting every error by kind and logging at most one per
//!   kind per interval.
//! - [`worker`]: [`Worker`], heavy work on its own thread fed by a slot of 1 (newest wins).
//!
//! Entry point in a service's `main`: `init_tracing()`, bind [`HttpArgs::addr`], spawn
//! `serve(listener, router(state), shutdown)`, run the pipeline until [`shutdown_signal`].

pub mod errors;
pub mod health;
pub mod healthcheck;
pub mod http;
pub mod metrics;
pub mod refusals;
mod shutdown;
mod telemetry;
pub mod worker;

pub use errors::ErrorReporter;
pub use health::{Readiness, ReadinessReport};
pub use healthcheck::{HealthcheckArgs, HealthcheckError, healthcheck};
pub use http::{
    HEADER_READ_TIMEOUT, HttpArgs, HttpLimits, HttpState, MAX_CONNECTIONS, router, serve,
    serve_with,
};
pub use metrics::{BuildInfo, Metrics};
pub use shutdown::shutdown_signal;
pub use telemetry::{init_tracing, init_tracing_to_file};
pub use worker::{Submitter, Worker};
