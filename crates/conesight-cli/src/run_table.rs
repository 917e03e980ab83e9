//! The table and summary `conesight run` prints of what its monitor (`run_monitor`) saw: one
//! row a second, the truth columns (matched cones, position error) only when the source is the
//! renderer, every column named and explained, then the summary and where the saved frames
//! went.

use std::collections::BTreeMap;
use std::path::Path;

use conesight_camera_service::CameraFrame;
use conesight_pipeline::match_cones;
use conesight_pipeline::stats::{fmt_opt, median, percentile};
use conesight_proto::LocatedCone;

use crate::draw::SavedFrame;

/// One frame's outcome as seen on the `cones` stream.
#[derive(Debug, Clone)]
pub struct FrameOutcome {
    /// Cones located.
    pub cones: usize,
    /// Range of the farthest, metres.
    pub farthest_m: Option<f64>,
    /// Acquisition to cones received.
    pub latency_ms: f64,
    /// Position errors of the cones matched to usable true cones, metres.
    pub errors_m: Vec<f64>,
    /// The same, as fractions of the true range.
    pub relative_errors: Vec<f64>,
    /// Usable true cones in the frame.
    pub usable_truth: usize,
}

/// What the monitor saw.
#[derive(Default)]
pub struct Summary {
    /// Each frame's outcome by frame sequence.
    pub outcomes: BTreeMap<u64, FrameOutcome>,
    /// Detections messages seen.
    pub detections_seen: u64,
    /// Keypoints messages seen.
    pub keypoints_seen: u64,
    /// How long the monitor watched.
    pub elapsed_secs: f64,
    /// The source has truth (the table and summary have error columns).
    pub with_truth: bool,
    /// The frames saved.
    pub saved: Vec<SavedFrame>,
    /// Why frames could not be saved.
    pub save_errors: Vec<String>,
    /// Frames due to be saved while the writer was busy.
    pub save_skipped: u64,
    /// Where the cone bases lay against the road of the extrinsics (the localiser's mount
    /// check, seen from the cones), once enough cones came.
    pub mount: Option<conesight_core::mount::MountCheckStatus>,
}

impl Summary {
    /// True when no cones message came.
    pub fn is_empty(&self) -> bool {
        self.outcomes.is_empty()
    }
}

/// A frame's outcome: its cones, the farthest, its latency and (with truth) its errors.
pub fn outcome(
    cones: &[LocatedCone],
    truth: Option<&CameraFrame>,
    latency_ms: f64,
) -> FrameOutcome {
    let (errors_m, relative_errors, usable_truth) = match truth.and_then(|f| f.frame.truth.as_ref())
    {
        Some(truth) => {
            let matches: Vec<_> = match_cones(cones, truth)
                .into_iter()
                .filter(|m| m.usable)
                .collect();
            (
                matches.iter().map(|m| m.error_m).collect(),
                matches.iter().map(|m| m.relative_error).collect(),
                truth.usable_count(),
            )
        }
        None => (Vec::new(), Vec::new(), 0),
    };
    FrameOutcome {
        cones: cones.len(),
        farthest_m: cones
            .iter()
            .map(|c| c.estimate.range_m())
            .max_by(f64::total_cmp),
        latency_ms,
        errors_m,
        relative_errors,
        usable_truth,
    }
}

/// The table's header and what its columns are; the truth columns only with truth.
pub fn print_header(with_truth: bool) {
    if with_truth {
        println!(
            "{:>5} {:>6} {:>6} {:>7} {:>11} {:>8} {:>9} {:>9} {:>7} {:>7}",
            "t_s",
            "frames",
            "hz",
            "cones/f",
            "max_range_m",
            "matched",
            "err_m",
            "err_%",
            "p50_ms",
            "p99_ms"
        );
        println!(
            "(t_s: seconds since the start; frames: frames with cones so far; hz: of them in the \
             last second; cones/f: median cones per frame; max_range_m: the farthest cone, m; \
             matched: cones matched to usable true cones / usable true cones; err_m, err_%: \
             median position error, m and % of range; p50_ms, p99_ms: end-to-end latency, \
             acquisition to cones, ms)"
        );
    } else {
        println!(
            "{:>5} {:>6} {:>6} {:>7} {:>11} {:>7} {:>7}",
            "t_s", "frames", "hz", "cones/f", "max_range_m", "p50_ms", "p99_ms"
        );
        println!(
            "(t_s: seconds since the start; frames: frames with cones so far; hz: of them in the \
             last second; cones/f: median cones per frame; max_range_m: the farthest cone, m; \
             p50_ms, p99_ms: end-to-end latency, acquisition to cones, ms; no truth for this \
             source, so no error columns)"
        );
    }
}

/// One row of the table: the frames of `window` (the last second's).
pub fn print_row(t_s: f64, summary: &Summary, window: &[u64]) {
    let outcomes: Vec<&FrameOutcome> = window
        .iter()
        .filter_map(|s| summary.outcomes.get(s))
        .collect();
    let cones: Vec<f64> = outcomes.iter().map(|o| o.cones as f64).collect();
    let farthest: Vec<f64> = outcomes.iter().filter_map(|o| o.farthest_m).collect();
    let latency: Vec<f64> = outcomes.iter().map(|o| o.latency_ms).collect();
    let common = format!(
        "{:>5.1} {:>6} {:>6} {:>7} {:>11}",
        t_s,
        summary.outcomes.len(),
        window.len(),
        fmt_opt(median(&cones), 1),
        fmt_opt(percentile(&farthest, 100.0), 1),
    );
    let latency = format!(
        "{:>7} {:>7}",
        fmt_opt(percentile(&latency, 50.0), 1),
        fmt_opt(percentile(&latency, 99.0), 1),
    );
    if !summary.with_truth {
        println!("{common} {latency}");
        return;
    }
    let errors: Vec<f64> = outcomes
        .iter()
        .flat_map(|o| o.errors_m.iter().copied())
        .collect();
    let relative: Vec<f64> = outcomes
        .iter()
        .flat_map(|o| o.relative_errors.iter().map(|e| 100.0 * e))
        .collect();
    let usable: usize = outcomes.iter().map(|o| o.usable_truth).sum();
    println!(
        "{common} {:>8} {:>9} {:>9} {latency}",
        format!("{}/{}", errors.len(), usable),
        fmt_opt(median(&errors), 3),
        fmt_opt(median(&relative), 2),
    );
}

impl Summary {
    /// Prints the summary: frames, cones, latency, the error against the truth (with truth),
    /// and where the saved frames went.
    pub fn print(&self, frames_asked: u64, save_every: u64, out: &Path) {
        let all: Vec<&FrameOutcome> = self.outcomes.values().collect();
        let latency: Vec<f64> = all.iter().map(|o| o.latency_ms).collect();
        let cones: usize = all.iter().map(|o| o.cones).sum();
        let farthest: Vec<f64> = all.iter().filter_map(|o| o.farthest_m).collect();
        let sent = if self.with_truth && frames_asked > 0 {
            format!(" out of {frames_asked} sent")
        } else {
            String::new()
        };
        println!(
            "\nsummary: {} frames with cones{sent} ({:.1} s, {:.1} Hz); {} detections and {} keypoints messages seen",
            all.len(),
            self.elapsed_secs,
            all.len() as f64 / self.elapsed_secs.max(1e-9),
            self.detections_seen,
            self.keypoints_seen
        );
        if self.with_truth {
            let errors: Vec<f64> = all
                .iter()
                .flat_map(|o| o.errors_m.iter().copied())
                .collect();
            let relative: Vec<f64> = all
                .iter()
                .flat_map(|o| o.relative_errors.iter().map(|e| 100.0 * e))
                .collect();
            let usable: usize = all.iter().map(|o| o.usable_truth).sum();
            println!(
                "  cones: {cones} ({:.1} per frame); matched to usable true cones: {}/{usable}; position error median {} m ({} % of range), p90 {} m",
                cones as f64 / all.len().max(1) as f64,
                errors.len(),
                fmt_opt(median(&errors), 3),
                fmt_opt(median(&relative), 2),
                fmt_opt(percentile(&errors, 90.0), 3),
            );
        } else {
            println!(
                "  cones: {cones} ({:.1} per frame), the farthest at {} m",
                cones as f64 / all.len().max(1) as f64,
                fmt_opt(percentile(&farthest, 100.0), 1),
            );
        }
        println!(
            "  end-to-end latency (acquisition -> cones received): p50 {} ms, p99 {} ms, max {} ms",
            fmt_opt(percentile(&latency, 50.0), 1),
            fmt_opt(percentile(&latency, 99.0), 1),
            fmt_opt(percentile(&latency, 100.0), 1)
        );
        if let Some(mount) = self.mount.filter(|m| m.mismatch) {
            println!(
                "  mount: {}: the extrinsics do not describe how the camera is mounted; estimate \
                 the mounting with `conesight mount --camera CALIBRATION.yaml --out mount.yaml \
                 FRAMES...` and pass --extrinsics mount.yaml",
                mount.describe()
            );
        }
        if save_every == 0 {
            return;
        }
        match (self.saved.first(), self.saved.last()) {
            (Some(first), Some(last)) => println!(
                "  saved {} annotated frames and bird's-eye views ({}) in {}: {} and {} ... {} (boxes in cone colour with class, score and range; keypoints magenta; a crimson cross where the range failed)",
                self.saved.len(),
                if save_every == 1 {
                    "every frame with cones".to_owned()
                } else {
                    format!("one frame with cones in {save_every}")
                },
                out.display(),
                first.frame.display(),
                first.bev.display(),
                last.frame.display(),
            ),
            _ => println!(
                "  no frame saved in {} (no frame with cones came)",
                out.display()
            ),
        }
        if self.save_skipped > 0 {
            println!(
                "  {} frames due to be saved were skipped: the writer was busy",
                self.save_skipped
            );
        }
        for error in &self.save_errors {
            eprintln!("saving a frame failed: {error}");
        }
    }
}
