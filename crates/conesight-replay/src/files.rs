//! [`recording_files`]: the files of the recordings a user names, as `conesight record` wrote
//! them: a file as it is, or the base name of a split recording (`drive.mcap` for
//! `drive_0000.mcap`, `drive_0001.mcap`, ...: `conesight_record::split_path`).

use std::path::{Path, PathBuf};

use conesight_record::split_path;

use crate::error::ReplayError;

/// The files of each recording of `inputs`, in order: an existing file as it is; else the
/// files of the split recording it is the base name of, by index. Neither is an error
/// naming the files looked for.
pub fn recording_files(inputs: &[PathBuf]) -> Result<Vec<PathBuf>, ReplayError> {
    let mut files = Vec::new();
    for input in inputs {
        if input.is_file() {
            files.push(input.clone());
            continue;
        }
        // A rosbag2 bag: its folder (metadata.yaml and its MCAP files).
        if input.is_dir() {
            let bag = conesight_ros2::bag::bag_files(input).map_err(|error| {
                ReplayError::NoRecording {
                    path: input.clone(),
                    first_split: PathBuf::from(error.to_string()),
                }
            })?;
            files.extend(bag);
            continue;
        }
        let parts = split_parts(input)?;
        if parts.is_empty() {
            return Err(ReplayError::NoRecording {
                path: input.clone(),
                first_split: split_path(input, 0, true),
            });
        }
        files.extend(parts);
    }
    Ok(files)
}

/// The files `conesight record` rolled the recording `base` into (`<stem>_NNNN.<ext>` beside
/// it), by index; none when there are none (or the folder is not there).
fn split_parts(base: &Path) -> Result<Vec<PathBuf>, ReplayError> {
    let (Some(stem), Some(name)) = (base.file_stem().and_then(|s| s.to_str()), base.file_name())
    else {
        return Ok(Vec::new());
    };
    let extension = base.extension().and_then(|e| e.to_str()).unwrap_or("mcap");
    let parent = match base.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let Ok(entries) = std::fs::read_dir(&parent) else {
        return Ok(Vec::new());
    };
    let prefix = format!("{stem}_");
    let suffix = format!(".{extension}");
    let mut parts = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|source| ReplayError::Io {
            path: parent.clone(),
            source,
        })?;
        let file_name = entry.file_name();
        let Some(file_name) = file_name.to_str() else {
            continue;
        };
        let index = file_name
            .strip_prefix(&prefix)
            .and_then(|rest| rest.strip_suffix(&suffix))
            .filter(|digits| digits.len() >= 4 && digits.bytes().all(|b| b.is_ascii_digit()))
            .and_then(|digits| digits.parse::<u64>().ok());
        if let Some(index) = index
            && entry.path().is_file()
            && entry.file_name() != name
        {
            parts.push((index, base.with_file_name(file_name)));
        }
    }
    parts.sort();
    Ok(parts.into_iter().map(|(_, path)| path).collect())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    /// A split recording named by its base name gives its files in order; a file given as it
    /// is stays; nothing at all names both places looked at.
    #[test]
    fn a_split_recording_is_found_by_its_base_name() {
        let dir =
            std::env::temp_dir().join(format!("conesight-recording-files-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let base = dir.join("drive.mcap");
        for index in [1, 0, 10] {
            std::fs::write(split_path(&base, index, true), b"x").unwrap();
        }
        std::fs::write(dir.join("drive_old.mcap"), b"x").unwrap();
        std::fs::write(dir.join("other.mcap"), b"x").unwrap();
        let names = |files: Vec<PathBuf>| -> Vec<String> {
            files
                .iter()
                .map(|f| f.file_name().unwrap().to_string_lossy().into_owned())
                .collect()
        };
        assert_eq!(
            names(recording_files(std::slice::from_ref(&base)).unwrap()),
            ["drive_0000.mcap", "drive_0001.mcap", "drive_0010.mcap"]
        );
        let other = dir.join("other.mcap");
        assert_eq!(
            names(recording_files(&[other, base]).unwrap()),
            [
                "other.mcap",
                "drive_0000.mcap",
                "drive_0001.mcap",
                "drive_0010.mcap"
            ]
        );
        let missing = dir.join("run.mcap");
        let error = recording_files(&[missing]).unwrap_err().to_string();
        assert!(
            error.contains("run.mcap") && error.contains("run_0000.mcap"),
            "{error}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
