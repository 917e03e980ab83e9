//! Replay jobs at scale: which recordings a worker takes ([`Shard`], [`list_recordings`]),
//! where their results go ([`ResultPaths`]: a results MCAP and a summary JSON per recording,
//! written under a temporary name and renamed, so a retried job overwrites its own result and
//! never leaves a second one), what a summary says ([`JobSummary`]), and the merge of every
//! summary of a results folder, optionally against a baseline folder ([`aggregate`]).
//!
//! The assignment needs no coordinator: the recordings are sorted by file name and recording
//! `i` goes to shard `i mod count`, so N workers given the same list and their own index
//! (Kubernetes' `JOB_COMPLETION_INDEX`, a swarm task slot minus one) split it exactly.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::diff::{DiffParams, DiffReport, RunCones, compare, read_cones};
use crate::error::ReplayError;

/// Extension of the recordings a folder is searched for.
pub const RECORDING_EXTENSION: &str = "mcap";
/// Suffix of a recording's results MCAP (`<stem>.cones.mcap`).
pub const RESULTS_SUFFIX: &str = ".cones.mcap";
/// Suffix of a recording's summary (`<stem>.summary.json`), written last: its presence says
/// the result is complete.
pub const SUMMARY_SUFFIX: &str = ".summary.json";
/// Suffix of a file being written; renamed into place when complete.
pub const PARTIAL_SUFFIX: &str = ".partial";

/// One worker's part of the list: recordings `i` with `i mod count == index`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Shard {
    /// 0-based index of this worker.
    pub index: usize,
    /// Number of workers.
    pub count: usize,
}

impl Shard {
    /// A shard, refusing a count of 0 and an index outside `0..count`.
    pub fn new(index: usize, count: usize) -> Result<Self, ReplayError> {
        if count == 0 {
            return Err(ReplayError::Options(
                "--shard-count must be at least 1 (the number of workers splitting the list)"
                    .to_owned(),
            ));
        }
        if index >= count {
            return Err(ReplayError::Options(format!(
                "shard index {index} is not below the shard count {count}: indices run 0..{count} \
                 (--shard-index, JOB_COMPLETION_INDEX) or 1..={count} (--shard-slot, a swarm \
                 task slot); set --shard-count to the number of workers"
            )));
        }
        Ok(Self { index, count })
    }

    /// The entries of the sorted `recordings` this shard takes, with their index in the list.
    pub fn select<'a>(&self, recordings: &'a [PathBuf]) -> Vec<(usize, &'a PathBuf)> {
        recordings
            .iter()
            .enumerate()
            .filter(|(i, _)| i % self.count == self.index)
            .collect()
    }
}

/// The recordings named by `inputs` (files, and folders searched for `*.mcap`, not
/// recursively), sorted by file name. Refuses a missing input, an empty result and two
/// recordings with the same file name (their results would collide).
pub fn list_recordings(inputs: &[PathBuf]) -> Result<Vec<PathBuf>, ReplayError> {
    let mut found = Vec::new();
    for input in inputs {
        if input.is_dir() {
            let entries = std::fs::read_dir(input).map_err(|source| ReplayError::Io {
                path: input.clone(),
                source,
            })?;
            for entry in entries {
                let path = entry
                    .map_err(|source| ReplayError::Io {
                        path: input.clone(),
                        source,
                    })?
                    .path();
                if path.is_file()
                    && path.extension().is_some_and(|e| e == RECORDING_EXTENSION)
                    && !is_result_file(&path)
                {
                    found.push(path);
                }
            }
        } else if input.is_file() {
            found.push(input.clone());
        } else {
            return Err(ReplayError::Options(format!(
                "no recording at {} (give .mcap files `conesight record` wrote, or folders of them)",
                input.display()
            )));
        }
    }
    found.sort_by(|a, b| a.file_name().cmp(&b.file_name()).then_with(|| a.cmp(b)));
    found.dedup();
    if found.is_empty() {
        return Err(ReplayError::Options(format!(
            "no .mcap recordings in {} (give .mcap files `conesight record` wrote, or folders of them)",
            crate::diff::describe(inputs)
        )));
    }
    for pair in found.windows(2) {
        if let [a, b] = pair
            && a.file_name() == b.file_name()
        {
            return Err(ReplayError::Options(format!(
                "{} and {} have the same file name, so their results would collide; rename one",
                a.display(),
                b.display()
            )));
        }
    }
    Ok(found)
}

fn is_result_file(path: &Path) -> bool {
    path.file_name()
        .and_then(|n| n.to_str())
        .is_some_and(|n| n.ends_with(RESULTS_SUFFIX) || n.starts_with('.'))
}

/// The name a recording's results are filed under: its file name without `.mcap`.
pub fn drive_name(recording: &Path) -> String {
    recording
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Where one recording's results go in the output folder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ResultPaths {
    /// `<out>/<drive>.cones.mcap`.
    pub results: PathBuf,
    /// `<out>/<drive>.summary.json`.
    pub summary: PathBuf,
}

impl ResultPaths {
    /// The result paths of `recording` under `out`.
    pub fn new(out: &Path, recording: &Path) -> Self {
        let drive = drive_name(recording);
        Self {
            results: out.join(format!("{drive}{RESULTS_SUFFIX}")),
            summary: out.join(format!("{drive}{SUMMARY_SUFFIX}")),
        }
    }

    /// The temporary name `path` is written under (a dot file beside it, so a folder listing
    /// skips it; the same name on every attempt, so a retry overwrites what a killed one left).
    pub fn partial(path: &Path) -> PathBuf {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        path.with_file_name(format!(".{name}{PARTIAL_SUFFIX}"))
    }
}

/// Writes `bytes` to `path` through its partial name, synced, then renamed into place.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ReplayError> {
    let partial = ResultPaths::partial(path);
    let io = |source| ReplayError::Io {
        path: partial.clone(),
        source,
    };
    let mut file = std::fs::File::create(&partial).map_err(io)?;
    file.write_all(bytes).map_err(io)?;
    file.sync_all().map_err(io)?;
    drop(file);
    rename_into_place(&partial, path)
}

/// Renames a finished partial file onto its final name (atomic on one file system).
pub fn rename_into_place(partial: &Path, path: &Path) -> Result<(), ReplayError> {
    std::fs::rename(partial, path).map_err(|source| ReplayError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// A model a job ran, by path and content.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ModelDigest {
    /// Path as the worker saw it.
    pub path: String,
    /// sha256, lowercase hex.
    pub sha256: String,
}

/// What one recording's job did (`<drive>.summary.json`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct JobSummary {
    /// The recording's file name without `.mcap`.
    pub drive: String,
    /// The recording as the worker saw it.
    pub recording: String,
    /// Its size, bytes.
    pub recording_bytes: u64,
    /// Its sha256: a result is reused only for the same content.
    pub recording_sha256: String,
    /// The results MCAP's file name (beside the summary).
    pub results: String,
    /// Index of the recording in the sorted list.
    pub list_index: usize,
    /// The shard that processed it.
    pub shard: Shard,
    /// Host name of the worker (a container id in swarm and Kubernetes).
    pub worker: String,
    /// Models by role (`detector`, `keypoints`).
    pub models: BTreeMap<String, ModelDigest>,
    /// The conesight version and git revision.
    pub conesight: String,
    /// Frames replayed.
    pub frames: u64,
    /// Frames whose cones came back.
    pub frames_answered: u64,
    /// Frames whose cones never came (within the frame timeout).
    pub frames_lost: u64,
    /// Cones in the results.
    pub cones: u64,
    /// Loading the services (models) for this recording, seconds.
    pub setup_s: f64,
    /// Replay from the first frame to the last cones, seconds.
    pub replay_s: f64,
    /// Everything for this recording, seconds.
    pub total_s: f64,
    /// Frames per second of the replay.
    pub frames_per_s: f64,
    /// When the job finished (Unix seconds).
    pub finished_unix_s: u64,
}

/// Reads one summary.
pub fn read_summary(path: &Path) -> Result<JobSummary, ReplayError> {
    let text = std::fs::read(path).map_err(|source| ReplayError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    serde_json::from_slice(&text).map_err(|error| {
        ReplayError::Options(format!(
            "{} is not a job summary ({error}); remove it and run the job again",
            path.display()
        ))
    })
}

/// Every `*.summary.json` of `dir`, sorted by drive.
pub fn read_summaries(dir: &Path) -> Result<Vec<JobSummary>, ReplayError> {
    let entries = std::fs::read_dir(dir).map_err(|source| ReplayError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut summaries = Vec::new();
    for entry in entries {
        let path = entry
            .map_err(|source| ReplayError::Io {
                path: dir.to_path_buf(),
                source,
            })?
            .path();
        let name = path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default();
        if name.ends_with(SUMMARY_SUFFIX) && !name.starts_with('.') {
            summaries.push(read_summary(&path)?);
        }
    }
    summaries.sort_by(|a, b| a.drive.cmp(&b.drive));
    Ok(summaries)
}

/// Totals over every drive of a results folder.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct Totals {
    /// Drives (summaries).
    pub drives: usize,
    /// Frames replayed.
    pub frames: u64,
    /// Frames whose cones never came.
    pub frames_lost: u64,
    /// Cones.
    pub cones: u64,
    /// Sum of the replay times, seconds (worker time).
    pub replay_s: f64,
    /// Sum of the per-recording times, seconds (worker time).
    pub total_s: f64,
    /// Frames over the summed replay time.
    pub frames_per_s: f64,
    /// Workers (host names) that wrote summaries.
    pub workers: Vec<String>,
    /// Model sha256s by role; more than one value for a role means the drives were not all
    /// processed by the same model.
    pub models: BTreeMap<String, Vec<String>>,
}

/// Merges summaries into totals.
pub fn totals(summaries: &[JobSummary]) -> Totals {
    let mut totals = Totals {
        drives: summaries.len(),
        ..Totals::default()
    };
    for s in summaries {
        totals.frames += s.frames;
        totals.frames_lost += s.frames_lost;
        totals.cones += s.cones;
        totals.replay_s += s.replay_s;
        totals.total_s += s.total_s;
        if !totals.workers.contains(&s.worker) {
            totals.workers.push(s.worker.clone());
        }
        for (role, model) in &s.models {
            let list = totals.models.entry(role.clone()).or_default();
            if !list.contains(&model.sha256) {
                list.push(model.sha256.clone());
            }
        }
    }
    totals.workers.sort();
    totals.frames_per_s = totals.frames as f64 / totals.replay_s.max(1e-9);
    totals
}

/// One results folder's cones against a baseline folder's, drive by drive and pooled.
#[derive(Debug, Clone, serde::Serialize)]
pub struct BaselineComparison {
    /// The baseline folder.
    pub baseline: PathBuf,
    /// Drives in both folders, with their diff.
    pub drives: Vec<(String, DiffReport)>,
    /// Drives only in the results folder.
    pub only_in_results: Vec<String>,
    /// Drives only in the baseline folder.
    pub only_in_baseline: Vec<String>,
    /// Every drive in both pooled into one diff (frames told apart by drive).
    pub pooled: DiffReport,
}

/// Compares the results MCAPs of `dir` (B) against those of `baseline` (A) for every drive in
/// both (`conesight diff` per drive, and pooled over all drives).
pub fn compare_folders(
    dir: &Path,
    baseline: &Path,
    params: &DiffParams,
) -> Result<BaselineComparison, ReplayError> {
    let ours = read_summaries(dir)?;
    let theirs = read_summaries(baseline)?;
    let theirs_by_drive: BTreeMap<&str, &JobSummary> =
        theirs.iter().map(|s| (s.drive.as_str(), s)).collect();
    let mut drives = Vec::new();
    let mut only_in_results = Vec::new();
    let mut pooled_a = RunCones::default();
    let mut pooled_b = RunCones::default();
    let (mut paths_a, mut paths_b) = (Vec::new(), Vec::new());
    for summary in &ours {
        let Some(base) = theirs_by_drive.get(summary.drive.as_str()) else {
            only_in_results.push(summary.drive.clone());
            continue;
        };
        let a = vec![baseline.join(&base.results)];
        let b = vec![dir.join(&summary.results)];
        let run_a = read_cones(&a)?;
        let run_b = read_cones(&b)?;
        drives.push((
            summary.drive.clone(),
            compare(&a, &b, &run_a, &run_b, params),
        ));
        pool(&mut pooled_a, run_a, &summary.drive);
        pool(&mut pooled_b, run_b, &summary.drive);
        paths_a.extend(a);
        paths_b.extend(b);
    }
    let ours_drives: Vec<&str> = ours.iter().map(|s| s.drive.as_str()).collect();
    let only_in_baseline = theirs
        .iter()
        .filter(|s| !ours_drives.contains(&s.drive.as_str()))
        .map(|s| s.drive.clone())
        .collect();
    let pooled = compare(&paths_a, &paths_b, &pooled_a, &pooled_b, params);
    Ok(BaselineComparison {
        baseline: baseline.to_path_buf(),
        drives,
        only_in_results,
        only_in_baseline,
        pooled,
    })
}

/// Adds one drive's frames to a pool, the camera key prefixed with the drive.
fn pool(into: &mut RunCones, run: RunCones, drive: &str) {
    for ((camera, sequence, occurrence), cones) in run.frames {
        into.frames
            .insert((format!("{drive}/{camera}"), sequence, occurrence), cones);
    }
    into.repeated_sequences += run.repeated_sequences;
    into.truncated |= run.truncated;
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(n: usize) -> Vec<PathBuf> {
        (0..n)
            .map(|i| PathBuf::from(format!("d{i}.mcap")))
            .collect()
    }

    #[test]
    fn shards_cover_the_list_exactly_once() {
        for count in 1..5 {
            let list = names(7);
            let mut seen = vec![0; list.len()];
            for index in 0..count {
                for (i, _) in Shard::new(index, count).unwrap().select(&list) {
                    seen[i] += 1;
                }
            }
            assert!(seen.iter().all(|n| *n == 1), "{count}: {seen:?}");
        }
    }

    #[test]
    fn bad_shards_are_refused_with_the_fix() {
        let error = Shard::new(2, 2).unwrap_err().to_string();
        assert!(error.contains("not below the shard count 2"), "{error}");
        assert!(
            Shard::new(0, 0)
                .unwrap_err()
                .to_string()
                .contains("at least 1")
        );
    }

    #[test]
    fn result_names_and_partials() {
        let paths = ResultPaths::new(Path::new("/out"), Path::new("/in/drive_03.mcap"));
        assert_eq!(paths.results, Path::new("/out/drive_03.cones.mcap"));
        assert_eq!(paths.summary, Path::new("/out/drive_03.summary.json"));
        assert_eq!(
            ResultPaths::partial(&paths.summary),
            Path::new("/out/.drive_03.summary.json.partial")
        );
    }

    #[test]
    fn listing_sorts_skips_results_and_refuses_collisions() {
        let dir = std::env::temp_dir().join(format!("conesight-job-list-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("sub")).unwrap();
        for name in ["b.mcap", "a.mcap", "a.cones.mcap", ".x.mcap", "notes.txt"] {
            std::fs::write(dir.join(name), b"x").unwrap();
        }
        let list = list_recordings(std::slice::from_ref(&dir)).unwrap();
        let got: Vec<_> = list.iter().map(|p| drive_name(p)).collect();
        assert_eq!(got, ["a", "b"]);
        std::fs::write(dir.join("sub/a.mcap"), b"x").unwrap();
        let error = list_recordings(&[dir.clone(), dir.join("sub/a.mcap")])
            .unwrap_err()
            .to_string();
        assert!(error.contains("same file name"), "{error}");
        let missing = list_recordings(&[dir.join("nope.mcap")])
            .unwrap_err()
            .to_string();
        assert!(missing.contains("no recording at"), "{missing}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
