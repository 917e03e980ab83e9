//! [`Metrics`]: the Prometheus metrics every service exports on `/metrics`.
//!
//! | metric | type | labels |
//! | --- | --- | --- |
//! | `conesight_frames_received_total` | counter | |
//! | `conesight_frames_processed_total` | counter | |
//! | `conesight_frames_dropped_total` | counter | |
//! | `conesight_shared_memory_messages_total` | counter | |
//! | `conesight_shared_memory_published_total` | counter | |
//! | `conesight_errors_total` | counter | `kind` |
//! | `conesight_frames_lost_total` | counter | `stream`: gaps in the input's frame sequence (of messages that passed validation) |
//! | `conesight_stream_restarts_total` | counter | `stream`: an input's sequence went back or jumped too far: a new stream (a restarted camera) |
//! | `conesight_source_restarts_total` | counter | (camera) restarts of a source that failed, ended or stalled |
//! | `conesight_stage_latency_seconds` | histogram | `stage` |
//! | `conesight_queue_depth` | gauge | |
//! | `conesight_start_time_seconds` | gauge | when the process started (a restarted service shows a new value) |
//! | `conesight_detections_masked_total` | counter | (detector) detections dropped in the ego mask |
//! | `conesight_detector_coverage_ratio` | gauge | (detector) share of the frame it covers |
//! | `conesight_cones_published_total` | counter | `class` (localiser) |
//! | `conesight_input_age_seconds` | gauge | seconds since the latest input (since start before the first) |
//! | `conesight_mount_mismatch` | gauge | (localiser) 1 while the cone bases do not lie on the road of the extrinsics, else 0 |
//! | `conesight_mount_base_height_meters` | gauge | (localiser) median height of recent cone bases (within 30 m) above that road |
//! | `conesight_mount_height_slope_ratio` | gauge | (localiser) their height's slope with range, metres per metre |
//! | `conesight_mount_check_cones` | gauge | (localiser) cones the mount check holds (it judges from 30) |
//! | `conesight_zenoh_refused_messages_total` | counter | messages Zenoh refused over its receive limit, in this process ([`crate::refusals`]) |
//! | `conesight_build_info` | gauge (1) | `version`, `git_revision`, `model`, `model_sha256` |
//!
//! A service's registry ([`Metrics::for_service`]) adds the labels `service` and `camera` to
//! every metric, so one Prometheus sees every service of every camera apart.

use std::borrow::Cow;
use std::time::Duration;

use prometheus_client::encoding::text::encode;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use std::sync::atomic::AtomicU64;

use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::{Histogram, exponential_buckets};
use prometheus_client::registry::Registry;

/// Prefix of every metric name.
pub const METRIC_PREFIX: &str = "conesight";
/// Smallest latency bucket, seconds (100 us).
pub const LATENCY_BUCKET_START_SECS: f64 = 1e-4;
/// Ratio between consecutive latency buckets.
pub const LATENCY_BUCKET_FACTOR: f64 = 2.0;
/// Number of latency buckets (100 us .. ~3.3 s).
pub const LATENCY_BUCKET_COUNT: u16 = 16;

/// A label set with one label.
type OneLabel = [(&'static str, &'static str); 1];

fn latency_histogram() -> Histogram {
    Histogram::new(exponential_buckets(
        LATENCY_BUCKET_START_SECS,
        LATENCY_BUCKET_FACTOR,
        LATENCY_BUCKET_COUNT,
    ))
}

/// The metrics of one service. Cheap to share (`Arc<Metrics>`); every method takes `&self`.
#[derive(Debug)]
pub struct Metrics {
    registry: Registry,
    frames_received: Counter,
    frames_processed: Counter,
    frames_dropped: Counter,
    shared_memory_messages: Counter,
    shared_memory_published: Counter,
    errors: Family<OneLabel, Counter>,
    frames_lost: Family<OneLabel, Counter>,
    stream_restarts: Family<OneLabel, Counter>,
    stage_latency: Family<OneLabel, Histogram, fn() -> Histogram>,
    queue_depth: Gauge,
    detections_masked: Counter,
    detector_coverage: Gauge<f64, AtomicU64>,
    source_restarts: Counter,
    cones_published: Family<OneLabel, Counter>,
    input_age: Gauge<f64, AtomicU64>,
    mount_mismatch: Gauge,
    mount_base_height: Gauge<f64, AtomicU64>,
    mount_height_slope: Gauge<f64, AtomicU64>,
    mount_check_cones: Gauge,
    build_info: Family<Vec<(&'static str, String)>, Gauge>,
    zenoh_refused: Counter,
    zenoh_refused_seen: AtomicU64,
}

/// What `conesight_build_info` says: the build and the model a service runs.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct BuildInfo {
    /// Crate version (`CARGO_PKG_VERSION`).
    pub version: String,
    /// Git revision the binary was built from (`unknown` outside a checkout).
    pub git_revision: String,
    /// The model's file name, empty for services without one.
    pub model: String,
    /// sha256 of the model file (hex), empty without one.
    pub model_sha256: String,
}

impl Default for Metrics {
    fn default() -> Self {
        Self::new()
    }
}

impl Metrics {
    /// A registry with every metric registered at zero, no constant labels.
    pub fn new() -> Self {
        Self::with_registry(Registry::with_prefix(METRIC_PREFIX))
    }

    /// The registry of one service: every metric carries `service="<service>"` and
    /// `camera="<camera>"`.
    pub fn for_service(service: &str, camera: &str) -> Self {
        let labels = [
            (Cow::Borrowed("service"), Cow::Owned(service.to_owned())),
            (Cow::Borrowed("camera"), Cow::Owned(camera.to_owned())),
        ];
        Self::with_registry(Registry::with_prefix_and_labels(
            METRIC_PREFIX,
            labels.into_iter(),
        ))
    }

    fn with_registry(mut registry: Registry) -> Self {
        let frames_received = Counter::default();
        let frames_processed = Counter::default();
        let frames_dropped = Counter::default();
        let shared_memory_messages = Counter::default();
        let shared_memory_published = Counter::default();
        let errors = Family::<OneLabel, Counter>::default();
        let frames_lost = Family::<OneLabel, Counter>::default();
        let stream_restarts = Family::<OneLabel, Counter>::default();
        let stage_latency = Family::<OneLabel, Histogram, fn() -> Histogram>::new_with_constructor(
            latency_histogram,
        );
        let queue_depth = Gauge::default();
        let detections_masked = Counter::default();
        let detector_coverage = Gauge::<f64, AtomicU64>::default();
        let source_restarts = Counter::default();
        let cones_published = Family::<OneLabel, Counter>::default();
        let input_age = Gauge::<f64, AtomicU64>::default();
        let mount_mismatch = Gauge::default();
        let mount_base_height = Gauge::<f64, AtomicU64>::default();
        let mount_height_slope = Gauge::<f64, AtomicU64>::default();
        let mount_check_cones = Gauge::default();
        registry.register(
            "mount_mismatch",
            "1 while the cone bases do not lie on the road of the extrinsics (their median height or its slope with range beyond the limits), else 0 (localiser)",
            mount_mismatch.clone(),
        );
        registry.register(
            "mount_base_height_meters",
            "Median height of the recent cone bases within 30 m above the road of the extrinsics (localiser)",
            mount_base_height.clone(),
        );
        registry.register(
            "mount_height_slope_ratio",
            "Slope of the recent cone bases' height with range, metres per metre (localiser)",
            mount_height_slope.clone(),
        );
        registry.register(
            "mount_check_cones",
            "Cones the mount check holds (localiser)",
            mount_check_cones.clone(),
        );
        let build_info = Family::<Vec<(&'static str, String)>, Gauge>::default();
        let zenoh_refused = Counter::default();
        registry.register(
            "zenoh_refused_messages",
            "Messages Zenoh refused before buffering them: over its receive limit (--max-message-mb), in this process",
            zenoh_refused.clone(),
        );
        registry.register(
            "cones_published",
            "Cones published, by class (localiser)",
            cones_published.clone(),
        );
        registry.register(
            "input_age_seconds",
            "Seconds since the latest input arrived (since start before the first)",
            input_age.clone(),
        );
        registry.register(
            "build_info",
            "Always 1: the build (version, git revision) and the model (file, sha256) of the service",
            build_info.clone(),
        );
        registry.register(
            "source_restarts",
            "Restarts of the frame source after it failed, ended or stalled (camera)",
            source_restarts.clone(),
        );
        registry.register(
            "detections_masked",
            "Detections dropped because they stood in the ego mask (detector)",
            detections_masked.clone(),
        );
        registry.register(
            "detector_coverage_ratio",
            "Share of the frame the detector covers: 1 minus the ego mask's share (detector)",
            detector_coverage.clone(),
        );
        registry.register(
            "frames_received",
            "Input messages received from the bus",
            frames_received.clone(),
        );
        registry.register(
            "frames_processed",
            "Inputs fully processed and published",
            frames_processed.clone(),
        );
        registry.register(
            "frames_dropped",
            "Inputs dropped unprocessed (replaced by a newer one or rejected)",
            frames_dropped.clone(),
        );
        registry.register(
            "shared_memory_messages",
            "Input messages that arrived in Zenoh shared memory (zero-copy, same host)",
            shared_memory_messages.clone(),
        );
        registry.register(
            "shared_memory_published",
            "Output messages written straight into Zenoh shared memory (frames, one copy)",
            shared_memory_published.clone(),
        );
        registry.register("errors", "Errors by kind", errors.clone());
        registry.register(
            "frames_lost",
            "Frames missing from an input stream (gaps in its frame sequence), by stream",
            frames_lost.clone(),
        );
        registry.register(
            "stream_restarts",
            "Input streams that started again: the frame sequence went back or jumped too far to be a gap (a restarted camera), by stream",
            stream_restarts.clone(),
        );
        registry.register(
            "stage_latency_seconds",
            "Time spent per pipeline stage",
            stage_latency.clone(),
        );
        registry.register(
            "queue_depth",
            "Inputs waiting for the worker",
            queue_depth.clone(),
        );
        // When this process started: a restarted service shows a new value (and its counters
        // start again from 0), so `changes(conesight_start_time_seconds[5m])` counts restarts.
        let start_time = Gauge::<f64, AtomicU64>::default();
        start_time.set(
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0.0, |d| d.as_secs_f64()),
        );
        registry.register(
            "start_time_seconds",
            "When this service process started, seconds since the Unix epoch (a restart shows a new value)",
            start_time,
        );
        Self {
            registry,
            frames_received,
            frames_processed,
            frames_dropped,
            shared_memory_messages,
            shared_memory_published,
            errors,
            frames_lost,
            stream_restarts,
            stage_latency,
            queue_depth,
            detections_masked,
            detector_coverage,
            source_restarts,
            cones_published,
            input_age,
            mount_mismatch,
            mount_base_height,
            mount_height_slope,
            mount_check_cones,
            build_info,
            zenoh_refused,
            zenoh_refused_seen: AtomicU64::new(0),
        }
    }

    /// Counts `count` cones of `class` published.
    pub fn cones_published(&self, class: &'static str, count: u64) {
        self.cones_published
            .get_or_create(&[("class", class)])
            .inc_by(count);
    }

    /// Cones of `class` published so far.
    pub fn cones_published_count(&self, class: &'static str) -> u64 {
        self.cones_published
            .get_or_create(&[("class", class)])
            .get()
    }

    /// Sets the age of the latest input, seconds.
    pub fn set_input_age(&self, seconds: f64) {
        self.input_age.set(seconds);
    }

    /// Sets what the mount check sees: the cones it holds, their bases' median height above
    /// the road of the extrinsics and its slope with range (0 when unknown), and whether that
    /// is a mismatch.
    pub fn set_mount_check(
        &self,
        cones: usize,
        median_height_m: f64,
        slope: Option<f64>,
        mismatch: bool,
    ) {
        self.mount_check_cones
            .set(i64::try_from(cones).unwrap_or(i64::MAX));
        self.mount_base_height.set(median_height_m);
        self.mount_height_slope.set(slope.unwrap_or(0.0));
        self.mount_mismatch.set(i64::from(mismatch));
    }

    /// Replaces `conesight_build_info` (one series, value 1).
    pub fn set_build_info(&self, info: &BuildInfo) {
        self.build_info.clear();
        self.build_info
            .get_or_create(&vec![
                ("version", info.version.clone()),
                ("git_revision", info.git_revision.clone()),
                ("model", info.model.clone()),
                ("model_sha256", info.model_sha256.clone()),
            ])
            .set(1);
    }

    /// Counts one restart of the frame source.
    pub fn source_restart(&self) {
        self.source_restarts.inc();
    }

    /// Restarts of the frame source so far.
    pub fn source_restart_count(&self) -> u64 {
        self.source_restarts.get()
    }

    /// Counts detections dropped in the ego mask.
    pub fn detections_masked(&self, count: u64) {
        self.detections_masked.inc_by(count);
    }

    /// Sets the share of the frame the detector covers.
    pub fn set_detector_coverage(&self, ratio: f64) {
        self.detector_coverage.set(ratio);
    }

    /// Counts one input received.
    pub fn frame_received(&self) {
        self.frames_received.inc();
    }

    /// Counts one input processed and published.
    pub fn frame_processed(&self) {
        self.frames_processed.inc();
    }

    /// Inputs received so far.
    pub fn frames_received_count(&self) -> u64 {
        self.frames_received.get()
    }

    /// Inputs processed so far.
    pub fn frames_processed_count(&self) -> u64 {
        self.frames_processed.get()
    }

    /// Inputs dropped so far.
    pub fn frames_dropped_count(&self) -> u64 {
        self.frames_dropped.get()
    }

    /// Counts one input dropped.
    pub fn frame_dropped(&self) {
        self.frames_dropped.inc();
    }

    /// Counts one input that arrived in shared memory.
    pub fn shared_memory_message(&self) {
        self.shared_memory_messages.inc();
    }

    /// Counts one output message written into shared memory.
    pub fn shared_memory_published(&self) {
        self.shared_memory_published.inc();
    }

    /// Input messages that arrived in shared memory so far.
    pub fn shared_memory_message_count(&self) -> u64 {
        self.shared_memory_messages.get()
    }

    /// Counts one error of `kind` (a short stable name such as `malformed_protobuf`).
    pub fn error(&self, kind: &'static str) {
        self.errors.get_or_create(&[("kind", kind)]).inc();
    }

    /// Counts `count` frames missing from `stream` (a gap in its frame sequence).
    pub fn frames_lost(&self, stream: &'static str, count: u64) {
        self.frames_lost
            .get_or_create(&[("stream", stream)])
            .inc_by(count);
    }

    /// Counts a restart of `stream`: its sequence went back or jumped too far to be a gap.
    pub fn stream_restarted(&self, stream: &'static str) {
        self.stream_restarts
            .get_or_create(&[("stream", stream)])
            .inc();
    }

    /// Records the time spent in `stage` (e.g. `decode`, `inference`, `pnp`, `end_to_end`).
    pub fn observe_stage(&self, stage: &'static str, elapsed: Duration) {
        self.stage_latency
            .get_or_create(&[("stage", stage)])
            .observe(elapsed.as_secs_f64());
    }

    /// Sets the number of inputs waiting for the worker.
    pub fn set_queue_depth(&self, depth: i64) {
        self.queue_depth.set(depth);
    }

    /// Errors of `kind` counted so far.
    pub fn error_count(&self, kind: &'static str) -> u64 {
        self.errors.get_or_create(&[("kind", kind)]).get()
    }

    /// The metrics in the Prometheus (OpenMetrics) text format.
    pub fn encode(&self) -> String {
        let total = crate::refusals::refused_messages();
        let seen = self
            .zenoh_refused_seen
            .swap(total, std::sync::atomic::Ordering::Relaxed);
        self.zenoh_refused.inc_by(total.saturating_sub(seen));
        let mut text = String::new();
        // Writing into a String cannot fail.
        let _ = encode(&mut text, &self.registry);
        text
    }
}

/// The value of `series` in a Prometheus text body, for tests and tools: `series` is `name` or
/// `name{label="value",...}`; a line matches when its metric name is `name` and it carries every
/// label given (others, such as `service` and `camera`, may be there too). The first match.
pub fn series_value(text: &str, series: &str) -> Option<f64> {
    let (name, wanted) = split_series(series);
    text.lines().find_map(|line| {
        if line.starts_with('#') {
            return None;
        }
        let (head, value) = line.rsplit_once(' ')?;
        let (line_name, labels) = split_series(head);
        (line_name == name && wanted.iter().all(|label| labels.contains(label)))
            .then(|| value.trim().parse().ok())
            .flatten()
    })
}

/// `name{a="1",b="2"}` -> (`name`, [`a="1"`, `b="2"`]); label values hold no commas here.
fn split_series(series: &str) -> (&str, Vec<&str>) {
    match series.split_once('{') {
        Some((name, rest)) => (
            name,
            rest.trim_end_matches('}')
                .split(',')
                .filter(|label| !label.is_empty())
                .collect(),
        ),
        None => (series, Vec::new()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_has_every_metric_with_values() {
        let metrics = Metrics::new();
        metrics.frame_received();
        metrics.frame_received();
        metrics.frame_processed();
        metrics.frame_dropped();
        metrics.shared_memory_message();
        metrics.error("malformed_protobuf");
        metrics.observe_stage("inference", Duration::from_millis(3));
        metrics.set_queue_depth(1);
        metrics.source_restart();
        let text = metrics.encode();
        for line in [
            "conesight_frames_received_total 2",
            "conesight_frames_processed_total 1",
            "conesight_frames_dropped_total 1",
            "conesight_shared_memory_messages_total 1",
            "conesight_errors_total{kind=\"malformed_protobuf\"} 1",
            "conesight_stage_latency_seconds_count{stage=\"inference\"} 1",
            "conesight_stage_latency_seconds_bucket{le=\"0.0016\",stage=\"inference\"} 0",
            "conesight_stage_latency_seconds_bucket{le=\"0.0032\",stage=\"inference\"} 1",
            "conesight_queue_depth 1",
            "conesight_source_restarts_total 1",
        ] {
            assert!(text.contains(line), "missing {line:?} in\n{text}");
        }
        assert_eq!(metrics.error_count("malformed_protobuf"), 1);
        assert_eq!(metrics.shared_memory_message_count(), 1);
        assert!(text.ends_with("# EOF\n"));
    }

    #[test]
    fn service_labels_build_info_and_cones_by_class() {
        let metrics = Metrics::for_service("localiser", "front");
        metrics.cones_published("blue", 3);
        metrics.cones_published("yellow", 1);
        metrics.set_input_age(0.25);
        metrics.set_mount_check(42, 0.5, Some(0.02), true);
        metrics.set_build_info(&BuildInfo {
            version: "0.1.0".into(),
            git_revision: "abc".into(),
            model: String::new(),
            model_sha256: String::new(),
        });
        metrics.set_build_info(&BuildInfo {
            version: "0.1.0".into(),
            git_revision: "abc".into(),
            model: "keypoints.onnx".into(),
            model_sha256: "00ff".into(),
        });
        let text = metrics.encode();
        for line in [
            "conesight_cones_published_total{service=\"localiser\",camera=\"front\",class=\"blue\"} 3",
            "conesight_cones_published_total{service=\"localiser\",camera=\"front\",class=\"yellow\"} 1",
            "conesight_input_age_seconds{service=\"localiser\",camera=\"front\"} 0.25",
            "conesight_mount_mismatch{service=\"localiser\",camera=\"front\"} 1",
            "conesight_mount_base_height_meters{service=\"localiser\",camera=\"front\"} 0.5",
            "conesight_mount_height_slope_ratio{service=\"localiser\",camera=\"front\"} 0.02",
            "conesight_mount_check_cones{service=\"localiser\",camera=\"front\"} 42",
            "conesight_build_info{service=\"localiser\",camera=\"front\",version=\"0.1.0\",git_revision=\"abc\",model=\"keypoints.onnx\",model_sha256=\"00ff\"} 1",
            "conesight_frames_received_total{service=\"localiser\",camera=\"front\"} 0",
        ] {
            assert!(text.contains(line), "missing {line:?} in\n{text}");
        }
        assert_eq!(
            series_value(&text, "conesight_cones_published_total{class=\"blue\"}"),
            Some(3.0)
        );
        assert_eq!(
            series_value(&text, "conesight_frames_received_total"),
            Some(0.0)
        );
        assert_eq!(
            series_value(&text, "conesight_cones_published_total{class=\"orange\"}"),
            None
        );
        // The model was set after start: one build_info series, not two.
        assert_eq!(text.matches("conesight_build_info{").count(), 1, "{text}");
        assert_eq!(metrics.cones_published_count("blue"), 3);
    }
}
