//! [`ErrorReporter`]: every error counted by kind, at most one log line per kind per interval.

use std::collections::HashMap;
use std::fmt::Display;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::metrics::Metrics;

/// Default time between two log lines of the same error kind.
pub const DEFAULT_LOG_INTERVAL: Duration = Duration::from_secs(5);

#[derive(Debug)]
struct KindState {
    last_logged: Instant,
    suppressed: u64,
}

/// Counts errors by kind in [`Metrics`] and logs them rate-limited, so a flood of bad input
/// neither fills the log nor goes unnoticed.
#[derive(Debug)]
pub struct ErrorReporter {
    metrics: Arc<Metrics>,
    interval: Duration,
    kinds: Mutex<HashMap<&'static str, KindState>>,
}

impl ErrorReporter {
    /// A reporter logging each kind at most once per `interval`.
    pub fn new(metrics: Arc<Metrics>, interval: Duration) -> Self {
        Self {
            metrics,
            interval,
            kinds: Mutex::new(HashMap::new()),
        }
    }

    /// Counts the error and logs it (warn) unless its kind was logged less than the interval
    /// ago; the log line says how many of that kind were suppressed since the last one.
    /// Returns whether it was logged.
    pub fn report(&self, kind: &'static str, error: &dyn Display) -> bool {
        self.metrics.error(kind);
        let now = Instant::now();
        let suppressed = {
            let Ok(mut kinds) = self.kinds.lock() else {
                // A panic elsewhere poisoned the lock; still log rather than lose errors.
                tracing::warn!(kind, %error, "error");
                return true;
            };
            match kinds.get_mut(kind) {
                Some(state) if now.duration_since(state.last_logged) < self.interval => {
                    state.suppressed += 1;
                    return false;
                }
                Some(state) => {
                    let suppressed = state.suppressed;
                    *state = KindState {
                        last_logged: now,
                        suppressed: 0,
                    };
                    suppressed
                }
                None => {
                    kinds.insert(
                        kind,
                        KindState {
                            last_logged: now,
                            suppressed: 0,
                        },
                    );
                    0
                }
            }
        };
        tracing::warn!(kind, suppressed, %error, "error");
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_everything_logs_once_per_interval_per_kind() {
        let metrics = Arc::new(Metrics::new());
        let reporter = ErrorReporter::new(metrics.clone(), Duration::from_millis(100));
        let logged: Vec<bool> = (0..50)
            .map(|i| reporter.report("malformed_protobuf", &format!("bad {i}")))
            .collect();
        assert_eq!(logged.iter().filter(|l| **l).count(), 1);
        assert!(reporter.report("image_size", &"wrong size"));
        assert_eq!(metrics.error_count("malformed_protobuf"), 50);
        assert_eq!(metrics.error_count("image_size"), 1);
        std::thread::sleep(Duration::from_millis(120));
        assert!(reporter.report("malformed_protobuf", &"again"));
    }
}
