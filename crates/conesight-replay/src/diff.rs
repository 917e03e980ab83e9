//! [`diff`]: the cones of two recordings of the same drive compared frame by frame (an old
//! model against a new one: the regression check of a model update).
//!
//! Frames are matched on camera and frame sequence, which every pipeline message copies from
//! its frame and a replay keeps (it stamps acquisition times anew); when a camera restarted
//! and its sequences repeat, the n-th occurrence in A meets the n-th in B. In a frame of both files, cones are matched
//! greedily, nearest pair first: a pair must have the same class and lie within the gate,
//! `gate_m + gate_fraction * range` of A's cone (1 m + 10 % by default), in the vehicle frame.
//! Cones of one class in a frame stand metres apart, so nearest-first agrees with an optimal
//! (Hungarian) assignment in all but contrived cases, and it is simple to reason about.
//! A matched pair falls in the range band of A's cone, an unmatched cone in its own; per band
//! the report gives the cones of each file, matched and unmatched counts and the median and
//! 95th percentile of the position change.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use conesight_bus::Stream;
use conesight_proto::pb;

use crate::error::ReplayError;
use crate::reader::{Recording, decode_message};

/// Matching parameters.
#[derive(Debug, Clone, serde::Serialize)]
pub struct DiffParams {
    /// Constant part of the gate, metres.
    pub gate_m: f64,
    /// Part of the gate proportional to the range, dimensionless.
    pub gate_fraction: f64,
    /// Lower edges of the range bands, metres (the last band is open-ended).
    pub band_edges_m: Vec<f64>,
}

impl Default for DiffParams {
    fn default() -> Self {
        Self {
            gate_m: 1.0,
            gate_fraction: 0.1,
            band_edges_m: vec![0.0, 10.0, 20.0, 30.0],
        }
    }
}

/// A frame's identity: camera, frame sequence, and which occurrence of that sequence in the
/// file (0 unless the camera restarted and its sequences repeat). Not the acquisition stamp:
/// a replay stamps frames anew.
pub type FrameKey = (String, u64, u32);

/// One cone as the diff sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiffCone {
    /// `pb::ConeClass` value.
    pub class: i32,
    /// Base centre in the vehicle frame, metres.
    pub position_in_vehicle_m: [f64; 3],
    /// Range from the camera, metres.
    pub range_m: f64,
}

/// The cones of every frame of one recording.
#[derive(Debug, Default)]
pub struct RunCones {
    /// Cones per frame.
    pub frames: BTreeMap<FrameKey, Vec<DiffCone>>,
    /// Cones messages whose camera and sequence were seen before (told apart by occurrence).
    pub repeated_sequences: u64,
    /// Whether a file ended short.
    pub truncated: bool,
}

/// Reads every cones message of the recording `paths`.
pub fn read_cones(paths: &[PathBuf]) -> Result<RunCones, ReplayError> {
    let mut recording = Recording::open(paths)?;
    let mut run = RunCones::default();
    let mut occurrences: BTreeMap<(String, u64), u32> = BTreeMap::new();
    while let Some(message) = recording.next_message()? {
        if message.stream != Stream::Cones {
            continue;
        }
        let path = recording.path(message.file).to_path_buf();
        let cones: pb::Cones = decode_message(&path, &message)?;
        let Some(header) = cones.header.as_ref() else {
            continue;
        };
        let seen = occurrences
            .entry((header.camera_id.clone(), header.frame_sequence))
            .or_insert(0_u32);
        let key = (header.camera_id.clone(), header.frame_sequence, *seen);
        if *seen > 0 {
            run.repeated_sequences += 1;
        }
        *seen += 1;
        let list = cones
            .cones
            .iter()
            .map(|cone| {
                let p = cone.position_in_vehicle_m.unwrap_or_default();
                DiffCone {
                    class: cone.detection.as_ref().map_or(0, |d| d.class),
                    position_in_vehicle_m: [p.x, p.y, p.z],
                    range_m: cone.range_m,
                }
            })
            .collect();
        run.frames.insert(key, list);
    }
    run.truncated = !recording.truncated().is_empty();
    Ok(run)
}

/// One range band's figures.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct BandSummary {
    /// `0-10`, `30+`, or `all`.
    pub band: String,
    /// Frames of both files with a cone of this band in either.
    pub frames_compared: u64,
    /// Cones of A in this band (compared frames only).
    pub cones_in_a: u64,
    /// Cones of B in this band (compared frames only).
    pub cones_in_b: u64,
    /// Matched pairs (by A's range).
    pub matched: u64,
    /// Cones of A without a match.
    pub only_in_a: u64,
    /// Cones of B without a match.
    pub only_in_b: u64,
    /// Median position change of the matched pairs, metres.
    pub median_change_m: Option<f64>,
    /// 95th percentile of the position change, metres.
    pub p95_change_m: Option<f64>,
    /// Largest position change, metres.
    pub max_change_m: Option<f64>,
}

/// One compared frame, for plots.
#[derive(Debug, Clone, serde::Serialize)]
pub struct FrameCount {
    /// Camera.
    pub camera: String,
    /// Frame sequence.
    pub sequence: u64,
    /// Cones in A.
    pub cones_in_a: usize,
    /// Cones in B.
    pub cones_in_b: usize,
}

/// One matched pair, for plots.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct MatchedPair {
    /// Range of A's cone, metres.
    pub range_m: f64,
    /// Distance between the two positions, metres.
    pub change_m: f64,
}

/// The comparison of two recordings.
#[derive(Debug, Clone, serde::Serialize)]
pub struct DiffReport {
    /// Recording A.
    pub a: Vec<PathBuf>,
    /// Recording B.
    pub b: Vec<PathBuf>,
    /// The matching parameters.
    pub params: DiffParams,
    /// Frames with cones in A.
    pub frames_in_a: u64,
    /// Frames with cones in B.
    pub frames_in_b: u64,
    /// Frames in both.
    pub frames_compared: u64,
    /// Frames only in A.
    pub frames_only_in_a: u64,
    /// Frames only in B.
    pub frames_only_in_b: u64,
    /// Frames whose cone count differs.
    pub frames_with_count_change: u64,
    /// Per band, then `all`.
    pub bands: Vec<BandSummary>,
    /// Every compared frame (not in the JSON summary).
    #[serde(skip)]
    pub frames: Vec<FrameCount>,
    /// Every matched pair (not in the JSON summary).
    #[serde(skip)]
    pub pairs: Vec<MatchedPair>,
}

impl DiffReport {
    /// The `all` row.
    pub fn total(&self) -> Option<&BandSummary> {
        self.bands.last()
    }

    /// True when both runs gave the same cones in the same places in every frame.
    pub fn is_zero_change(&self) -> bool {
        self.frames_only_in_a == 0
            && self.frames_only_in_b == 0
            && self.total().is_some_and(|t| {
                t.only_in_a == 0 && t.only_in_b == 0 && t.max_change_m.unwrap_or(0.0) == 0.0
            })
    }
}

/// Compares the cones of recordings `a` and `b` (see the module docs).
pub fn diff(a: &[PathBuf], b: &[PathBuf], params: &DiffParams) -> Result<DiffReport, ReplayError> {
    let run_a = read_cones(a)?;
    let run_b = read_cones(b)?;
    Ok(compare(a, b, &run_a, &run_b, params))
}

/// [`diff`] on cones already read.
pub fn compare(
    a: &[PathBuf],
    b: &[PathBuf],
    run_a: &RunCones,
    run_b: &RunCones,
    params: &DiffParams,
) -> DiffReport {
    let bands = params.band_edges_m.len().max(1);
    let band_of = |range_m: f64| {
        params
            .band_edges_m
            .iter()
            .rposition(|edge| range_m >= *edge)
            .unwrap_or(0)
    };
    let mut rows = vec![BandSummary::default(); bands];
    let mut changes: Vec<Vec<f64>> = vec![Vec::new(); bands];
    let mut frames = Vec::new();
    let mut pairs = Vec::new();
    let mut report = DiffReport {
        a: a.to_vec(),
        b: b.to_vec(),
        params: params.clone(),
        frames_in_a: run_a.frames.len() as u64,
        frames_in_b: run_b.frames.len() as u64,
        frames_compared: 0,
        frames_only_in_a: 0,
        frames_only_in_b: run_b
            .frames
            .keys()
            .filter(|k| !run_a.frames.contains_key(*k))
            .count() as u64,
        frames_with_count_change: 0,
        bands: Vec::new(),
        frames: Vec::new(),
        pairs: Vec::new(),
    };
    for (key, cones_a) in &run_a.frames {
        let Some(cones_b) = run_b.frames.get(key) else {
            report.frames_only_in_a += 1;
            continue;
        };
        report.frames_compared += 1;
        if cones_a.len() != cones_b.len() {
            report.frames_with_count_change += 1;
        }
        frames.push(FrameCount {
            camera: key.0.clone(),
            sequence: key.1,
            cones_in_a: cones_a.len(),
            cones_in_b: cones_b.len(),
        });
        let mut touched = vec![false; bands];
        for cone in cones_a {
            let band = band_of(cone.range_m);
            rows[band].cones_in_a += 1;
            touched[band] = true;
        }
        for cone in cones_b {
            let band = band_of(cone.range_m);
            rows[band].cones_in_b += 1;
            touched[band] = true;
        }
        for (band, touched) in touched.iter().enumerate() {
            if *touched {
                rows[band].frames_compared += 1;
            }
        }
        let (matched, only_a, only_b) = match_frame(cones_a, cones_b, params);
        for (i, j, change_m) in matched {
            let band = band_of(cones_a[i].range_m);
            rows[band].matched += 1;
            changes[band].push(change_m);
            pairs.push(MatchedPair {
                range_m: cones_a[i].range_m,
                change_m,
            });
            let _ = j;
        }
        for i in only_a {
            rows[band_of(cones_a[i].range_m)].only_in_a += 1;
        }
        for j in only_b {
            rows[band_of(cones_b[j].range_m)].only_in_b += 1;
        }
    }
    let mut total = BandSummary {
        band: "all".to_owned(),
        frames_compared: report.frames_compared,
        ..BandSummary::default()
    };
    let mut all_changes = Vec::new();
    for (band, (row, band_changes)) in rows.iter_mut().zip(&changes).enumerate() {
        row.band = band_name(&params.band_edges_m, band);
        fill_changes(row, band_changes);
        total.cones_in_a += row.cones_in_a;
        total.cones_in_b += row.cones_in_b;
        total.matched += row.matched;
        total.only_in_a += row.only_in_a;
        total.only_in_b += row.only_in_b;
        all_changes.extend_from_slice(band_changes);
    }
    fill_changes(&mut total, &all_changes);
    rows.push(total);
    report.bands = rows;
    report.frames = frames;
    report.pairs = pairs;
    report
}

fn band_name(edges: &[f64], band: usize) -> String {
    let low = edges.get(band).copied().unwrap_or(0.0);
    match edges.get(band + 1) {
        Some(high) => format!("{low:.0}-{high:.0}"),
        None => format!("{low:.0}+"),
    }
}

fn fill_changes(row: &mut BandSummary, changes: &[f64]) {
    let mut sorted = changes.to_vec();
    sorted.sort_by(f64::total_cmp);
    row.median_change_m = percentile(&sorted, 50.0);
    row.p95_change_m = percentile(&sorted, 95.0);
    row.max_change_m = sorted.last().copied();
}

/// Linear-interpolated percentile of sorted values; `None` when empty.
pub fn percentile(sorted: &[f64], p: f64) -> Option<f64> {
    let last = sorted.len().checked_sub(1)?;
    let rank = p.clamp(0.0, 100.0) / 100.0 * last as f64;
    let low = rank.floor() as usize;
    let high = rank.ceil() as usize;
    let t = rank - low as f64;
    Some(sorted[low] * (1.0 - t) + sorted[high.min(last)] * t)
}

/// Pairs `(i in A, j in B, distance m)`, unmatched indices of A, unmatched indices of B.
pub type FrameMatches = (Vec<(usize, usize, f64)>, Vec<usize>, Vec<usize>);

/// Greedy nearest-first matching of one frame: (pairs `(i in A, j in B, distance m)`,
/// unmatched indices of A, unmatched indices of B).
pub fn match_frame(a: &[DiffCone], b: &[DiffCone], params: &DiffParams) -> FrameMatches {
    let mut candidates = Vec::new();
    for (i, cone_a) in a.iter().enumerate() {
        let gate = params.gate_m + params.gate_fraction * cone_a.range_m.abs();
        for (j, cone_b) in b.iter().enumerate() {
            if cone_a.class != cone_b.class {
                continue;
            }
            let d = distance(&cone_a.position_in_vehicle_m, &cone_b.position_in_vehicle_m);
            if d <= gate {
                candidates.push((d, i, j));
            }
        }
    }
    candidates.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)).then(x.2.cmp(&y.2)));
    let mut used_a = vec![false; a.len()];
    let mut used_b = vec![false; b.len()];
    let mut pairs = Vec::new();
    for (d, i, j) in candidates {
        if !used_a[i] && !used_b[j] {
            used_a[i] = true;
            used_b[j] = true;
            pairs.push((i, j, d));
        }
    }
    let only_a = (0..a.len()).filter(|i| !used_a[*i]).collect();
    let only_b = (0..b.len()).filter(|j| !used_b[*j]).collect();
    (pairs, only_a, only_b)
}

fn distance(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// The path list of one side, for messages.
pub fn describe(paths: &[PathBuf]) -> String {
    paths
        .iter()
        .map(|p| Path::new(p).display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cone(class: i32, x: f64, y: f64) -> DiffCone {
        DiffCone {
            class,
            position_in_vehicle_m: [x, y, 0.0],
            range_m: (x * x + y * y).sqrt(),
        }
    }

    #[test]
    fn nearest_pairs_of_one_class_within_the_gate_match() {
        let params = DiffParams::default();
        let a = [cone(1, 5.0, 1.5), cone(2, 5.0, -1.5), cone(1, 25.0, 1.5)];
        // Same blue cone moved 0.2 m, yellow swapped class (no match), far blue moved 3.4 m:
        // gate at 25 m is 1 + 2.5 = 3.5 m.
        let b = [cone(1, 5.2, 1.5), cone(1, 5.0, -1.5), cone(1, 28.4, 1.5)];
        let (pairs, only_a, only_b) = match_frame(&a, &b, &params);
        assert_eq!(pairs.len(), 2);
        assert_eq!((pairs[0].0, pairs[0].1), (0, 0));
        assert!((pairs[0].2 - 0.2).abs() < 1e-9);
        assert_eq!((pairs[1].0, pairs[1].1), (2, 2));
        assert_eq!(only_a, vec![1]);
        assert_eq!(only_b, vec![1]);
    }

    #[test]
    fn a_run_against_itself_is_zero_change_and_a_moved_run_is_not() {
        let mut run = RunCones::default();
        for seq in 0..5 {
            run.frames.insert(
                ("front".into(), seq, 0),
                vec![cone(1, 5.0, 1.5), cone(2, 15.0, -1.5), cone(3, 35.0, 0.0)],
            );
        }
        let paths = [PathBuf::from("a.mcap")];
        let report = compare(&paths, &paths, &run, &run, &DiffParams::default());
        assert!(report.is_zero_change());
        assert_eq!(report.frames_compared, 5);
        let names: Vec<_> = report.bands.iter().map(|b| b.band.as_str()).collect();
        assert_eq!(names, ["0-10", "10-20", "20-30", "30+", "all"]);
        assert_eq!(report.bands[0].matched, 5);
        assert_eq!(report.bands[2].frames_compared, 0);
        let mut moved = RunCones::default();
        for (key, cones) in &run.frames {
            let mut cones = cones.clone();
            cones[1].position_in_vehicle_m[0] += 0.5;
            moved.frames.insert(key.clone(), cones);
        }
        moved.frames.remove(&("front".into(), 4, 0));
        let report = compare(&paths, &paths, &run, &moved, &DiffParams::default());
        assert!(!report.is_zero_change());
        assert_eq!(report.frames_only_in_a, 1);
        let band = &report.bands[1];
        assert!((band.median_change_m.unwrap() - 0.5).abs() < 1e-9);
        assert_eq!(report.bands[0].max_change_m, Some(0.0));
    }

    #[test]
    fn percentiles_interpolate() {
        assert_eq!(percentile(&[], 50.0), None);
        assert_eq!(percentile(&[1.0, 2.0, 3.0], 50.0), Some(2.0));
        assert!((percentile(&[0.0, 1.0], 95.0).unwrap() - 0.95).abs() < 1e-12);
    }
}
