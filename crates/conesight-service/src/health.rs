//! [`Readiness`]: what `/readyz` reports, set by the service as it starts and runs.

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// Default freshness limit of the last input.
pub const DEFAULT_MAX_INPUT_AGE: Duration = Duration::from_secs(2);

/// Readiness of a service: model loaded, bus session up, last input fresh. Shared as
/// `Arc<Readiness>`; every method takes `&self`.
#[derive(Debug)]
pub struct Readiness {
    started: Instant,
    model_loaded: AtomicBool,
    session_up: AtomicBool,
    /// The frame source delivers (always true for services without a source of their own).
    source_up: AtomicBool,
    /// Nanoseconds after `started` of the last input, plus one (0 = no input yet).
    last_input_ns: AtomicU64,
    max_input_age: Option<Duration>,
    details: Mutex<Vec<(String, String)>>,
}

/// One readiness check's answer.
#[derive(Debug, Clone, PartialEq)]
pub struct ReadinessReport {
    /// The model (or whatever the service needs loaded) is loaded.
    pub model_loaded: bool,
    /// The Zenoh session is open.
    pub session_up: bool,
    /// The frame source delivers (a camera's; true for services without a source).
    pub source_up: bool,
    /// Seconds since the last input; `None` before the first.
    pub input_age_secs: Option<f64>,
    /// The last input is recent enough (always true for services without inputs).
    pub inputs_fresh: bool,
    /// What the service says about itself (e.g. the detector's coverage), one line each.
    pub details: Vec<(String, String)>,
}

impl ReadinessReport {
    /// Ready to serve: every condition holds.
    pub fn is_ready(&self) -> bool {
        self.model_loaded && self.session_up && self.source_up && self.inputs_fresh
    }

    /// `ready`/`not ready` and each condition, one per line.
    pub fn to_text(&self) -> String {
        let age = self
            .input_age_secs
            .map_or_else(|| "none".to_owned(), |secs| format!("{secs:.3}"));
        let mut text = format!(
            "{}\nmodel_loaded {}\nsession_up {}\nsource_up {}\ninputs_fresh {}\ninput_age_secs {age}\n",
            if self.is_ready() {
                "ready"
            } else {
                "not ready"
            },
            self.model_loaded,
            self.session_up,
            self.source_up,
            self.inputs_fresh,
        );
        for (key, value) in &self.details {
            text.push_str(&format!("{key} {}\n", value.replace('\n', " ")));
        }
        text
    }
}

impl Readiness {
    /// Readiness of a service whose inputs must be at most `max_input_age` old; `None` for a
    /// source (a camera) that has no inputs. Nothing is loaded or up yet.
    pub fn new(max_input_age: Option<Duration>) -> Self {
        Self {
            started: Instant::now(),
            model_loaded: AtomicBool::new(false),
            session_up: AtomicBool::new(false),
            source_up: AtomicBool::new(true),
            last_input_ns: AtomicU64::new(0),
            max_input_age,
            details: Mutex::new(Vec::new()),
        }
    }

    /// Sets (or replaces) a detail line `key value` of the report.
    pub fn set_detail(&self, key: &str, value: String) {
        let mut details = self
            .details
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        match details.iter_mut().find(|(k, _)| k == key) {
            Some(entry) => entry.1 = value,
            None => details.push((key.to_owned(), value)),
        }
    }

    /// Records whether the model is loaded (services without a model set `true` at start).
    pub fn set_model_loaded(&self, loaded: bool) {
        self.model_loaded.store(loaded, Ordering::Relaxed);
    }

    /// Records whether the Zenoh session is open.
    pub fn set_session_up(&self, up: bool) {
        self.session_up.store(up, Ordering::Relaxed);
    }

    /// Records whether the frame source delivers (a camera whose source failed, ended or
    /// stalled is not ready until frames come again).
    pub fn set_source_up(&self, up: bool) {
        self.source_up.store(up, Ordering::Relaxed);
    }

    /// Records that an input arrived now.
    pub fn mark_input(&self) {
        let since_start = u64::try_from(self.started.elapsed().as_nanos()).unwrap_or(u64::MAX);
        self.last_input_ns
            .store(since_start.saturating_add(1), Ordering::Relaxed);
    }

    /// Time since the latest input, or since start before the first.
    pub fn input_age_or_uptime(&self) -> Duration {
        let last = self.last_input_ns.load(Ordering::Relaxed);
        let elapsed = self.started.elapsed();
        if last == 0 {
            elapsed
        } else {
            elapsed.saturating_sub(Duration::from_nanos(last - 1))
        }
    }

    /// The current state.
    pub fn report(&self) -> ReadinessReport {
        let last = self.last_input_ns.load(Ordering::Relaxed);
        let input_age = (last > 0).then(|| {
            self.started
                .elapsed()
                .saturating_sub(Duration::from_nanos(last - 1))
        });
        let inputs_fresh = match (self.max_input_age, input_age) {
            (None, _) => true,
            (Some(max), Some(age)) => age <= max,
            (Some(_), None) => false,
        };
        ReadinessReport {
            model_loaded: self.model_loaded.load(Ordering::Relaxed),
            session_up: self.session_up.load(Ordering::Relaxed),
            source_up: self.source_up.load(Ordering::Relaxed),
            input_age_secs: input_age.map(|age| age.as_secs_f64()),
            inputs_fresh,
            details: self
                .details
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ready_only_when_everything_holds() {
        let readiness = Readiness::new(Some(Duration::from_millis(50)));
        assert!(!readiness.report().is_ready());
        readiness.set_model_loaded(true);
        readiness.set_session_up(true);
        let report = readiness.report();
        assert!(!report.inputs_fresh && report.input_age_secs.is_none());
        readiness.mark_input();
        assert!(readiness.report().is_ready());
        std::thread::sleep(Duration::from_millis(80));
        let stale = readiness.report();
        assert!(!stale.is_ready());
        assert!(stale.input_age_secs.unwrap() >= 0.08);
        assert!(stale.to_text().starts_with("not ready\n"));
        readiness.mark_input();
        readiness.set_session_up(false);
        assert!(!readiness.report().is_ready());
    }

    #[test]
    fn sources_need_no_inputs() {
        let readiness = Readiness::new(None);
        readiness.set_model_loaded(true);
        readiness.set_session_up(true);
        assert!(readiness.report().is_ready());
        assert!(readiness.report().to_text().starts_with("ready\n"));
        readiness.set_source_up(false);
        let down = readiness.report();
        assert!(!down.is_ready() && !down.source_up);
        assert!(down.to_text().contains("\nsource_up false\n"));
        readiness.set_source_up(true);
        assert!(readiness.report().is_ready());
    }
}
