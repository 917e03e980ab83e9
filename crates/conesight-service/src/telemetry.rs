//! Tracing set-up, once per process, from `RUST_LOG`. Logs go to stderr (stdout is left to a
//! command's own output, e.g. `conesight run`'s live table or `predict`'s JSON lines), or to a
//! file.

use std::fs::{File, OpenOptions};
use std::io::IsTerminal;
use std::path::Path;
use std::sync::Mutex;

use tracing_subscriber::EnvFilter;
use tracing_subscriber::Layer;
use tracing_subscriber::filter::filter_fn;
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::util::SubscriberInitExt;

use crate::refusals::{RefusalCounter, is_refusal_event};

/// Filter used when `RUST_LOG` is unset or invalid: our crates at info, ONNX Runtime, Zenoh
/// and Dust DDS only from warn (their info lines drown the services' own).
pub(crate) const DEFAULT_LOG_FILTER: &str = "info,ort=warn,zenoh=warn,zenoh_transport=warn,\
     zenoh_link_tcp=warn,zenoh_shm=warn,dust_dds=warn";

/// Installs the one formatting subscriber of the process on `writer`, filtered by `RUST_LOG`
/// (default [`DEFAULT_LOG_FILTER`]). A second call does nothing (tests may call it from many
/// places).
fn install<W>(writer: W, ansi: bool)
where
    W: for<'w> tracing_subscriber::fmt::MakeWriter<'w> + Send + Sync + 'static,
{
    let mut filter =
        EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(DEFAULT_LOG_FILTER));
    // Dust DDS logs every sample's bytes at info: kept to warn unless RUST_LOG names it.
    if !std::env::var("RUST_LOG").is_ok_and(|v| v.contains("dust_dds"))
        && let Ok(directive) = "dust_dds=warn".parse()
    {
        filter = filter.add_directive(directive);
    }
    let logs = tracing_subscriber::fmt::layer()
        .with_target(true)
        .with_ansi(ansi)
        .with_writer(writer)
        .with_filter(filter);
    // Zenoh's refusals of oversize messages are counted whatever RUST_LOG says.
    let refusals = RefusalCounter.with_filter(filter_fn(is_refusal_event));
    // Err only when a subscriber is already installed, which is fine.
    let _ = tracing_subscriber::registry()
        .with(logs)
        .with(refusals)
        .try_init();
}

/// Installs a formatting subscriber on stderr (colours only on a terminal) filtered by
/// `RUST_LOG` (default: our crates at info, ort and zenoh at warn).
pub fn init_tracing() {
    install(std::io::stderr, std::io::stderr().is_terminal());
}

/// Like [`init_tracing`], but appends the log lines (no colours) to `path`, creating it and
/// its folder: for a command that draws on the terminal, so log lines never land inside
/// what it draws.
///
/// # Errors
/// The file cannot be created or opened for appending (the message names it).
pub fn init_tracing_to_file(path: &Path) -> std::io::Result<()> {
    let open = || -> std::io::Result<File> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)?;
        }
        OpenOptions::new().create(true).append(true).open(path)
    };
    let file = open()
        .map_err(|e| std::io::Error::new(e.kind(), format!("log file {}: {e}", path.display())))?;
    install(Mutex::new(file), false);
    Ok(())
}
