//! [`FolderFrames`]: the images of a folder in name order, once (or looped), decoded when due
//! and kept within a memory budget.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use conesight_pipeline::SourceFrame;
use conesight_pipeline::boxes::read_boxes;
use conesight_pipeline::source::{list_images, read_image};

use crate::{Calibration, CameraFrame, FrameSource, Next, Pacing, SourceError};

/// The images of a folder, in name order, once: after the last one the source is finished
/// (`Next::Finished`), or with `looped` it starts again. Listed at start; each image is decoded when
/// it is first due (the one after it is decoded ahead on a thread meanwhile) and kept for the
/// next loops while the decoded frames fit in the cache budget, so the first frame goes out
/// after one decode and a folder of any size runs in bounded memory. An unreadable image (or
/// label file, with labels) is logged once and skipped on every loop.
#[derive(Debug)]
pub struct FolderFrames {
    dir: PathBuf,
    paths: Vec<PathBuf>,
    calibration: Calibration,
    /// Where the label files are, when the boxes are wanted.
    labels: Option<PathBuf>,
    budget_bytes: usize,
    cache: Vec<Option<CameraFrame>>,
    cached_bytes: usize,
    unreadable: Vec<bool>,
    /// The image being decoded ahead: (index, thread).
    ahead: Option<(usize, JoinHandle<Result<CameraFrame, SourceError>>)>,
    /// Images given so far, in all loops (the next one is `cursor % len`).
    cursor: usize,
    /// Start again after the last image.
    looped: bool,
    /// Images given.
    given: u64,
    /// Images found unreadable since [`FrameSource::take_skipped`] was last called.
    skipped: Vec<SourceError>,
}

/// Decodes image `index` of a folder (and its labels when `labels` is set).
fn read_folder_frame(
    index: usize,
    path: &Path,
    calibration: Calibration,
    labels: Option<&Path>,
) -> Result<CameraFrame, SourceError> {
    let image = read_image(path)?;
    let boxes = match labels {
        Some(dir) => read_boxes(
            &dir.join(path.with_extension("txt").file_name().unwrap_or_default()),
            image.width(),
            image.height(),
        )?,
        None => Vec::new(),
    };
    Ok(CameraFrame {
        frame: SourceFrame {
            index: index as u64,
            name: path.display().to_string(),
            image: Arc::new(image),
            camera: calibration.camera,
            extrinsics: calibration.extrinsics,
            truth: None,
        },
        boxes,
        acquisition_ns: None,
    })
}

impl FolderFrames {
    /// The images of `dir` (at least one file with an image extension), decoded later; the
    /// label files of `labels` give each image's boxes; decoded frames are kept within
    /// `cache_mb` MiB (for the next loops when `looped`). The first image's size (its header alone is read) must be the
    /// calibration's, so a calibration of another camera or mode is refused before anything
    /// starts.
    pub fn new(
        dir: &Path,
        calibration: Calibration,
        labels: Option<PathBuf>,
        cache_mb: usize,
        looped: bool,
    ) -> Result<Self, SourceError> {
        let paths = list_images(dir)?;
        let camera = &calibration.camera;
        // An unreadable first image is skipped when it is due, as any other.
        if let Some((path, Ok((width_px, height_px)))) = paths
            .first()
            .map(|path| (path, image::image_dimensions(path)))
            && (width_px, height_px) != (camera.width_px, camera.height_px)
        {
            return Err(SourceError::SizeMismatch {
                source_name: format!("folder:{}", dir.display()),
                frame: path.display().to_string(),
                width_px,
                height_px,
                expected_width_px: camera.width_px,
                expected_height_px: camera.height_px,
            });
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            cache: vec![None; paths.len()],
            unreadable: vec![false; paths.len()],
            paths,
            calibration,
            labels,
            budget_bytes: cache_mb.saturating_mul(1 << 20),
            cached_bytes: 0,
            ahead: None,
            cursor: 0,
            looped,
            given: 0,
            skipped: Vec::new(),
        })
    }

    /// Number of image files listed.
    pub fn len(&self) -> usize {
        self.paths.len()
    }

    /// True when no file is listed (never: [`FolderFrames::new`] refuses an empty folder).
    pub fn is_empty(&self) -> bool {
        self.paths.is_empty()
    }

    /// Decoded frames kept for the next loops.
    pub fn cached(&self) -> usize {
        self.cache.iter().flatten().count()
    }

    fn decode_ahead(&self, index: usize) -> JoinHandle<Result<CameraFrame, SourceError>> {
        let (path, calibration, labels) = (
            self.paths[index].clone(),
            self.calibration,
            self.labels.clone(),
        );
        std::thread::spawn(move || read_folder_frame(index, &path, calibration, labels.as_deref()))
    }

    fn decode(&mut self, index: usize) -> Result<CameraFrame, SourceError> {
        match self.ahead.take() {
            Some((ahead, thread)) if ahead == index => thread.join().unwrap_or_else(|_| {
                Err(SourceError::Failed {
                    source_name: self.name(),
                    reason: "the decoding thread panicked".to_owned(),
                })
            }),
            // A stale look-ahead (the image after a skipped one) finishes on its own.
            _ => read_folder_frame(
                index,
                &self.paths[index],
                self.calibration,
                self.labels.as_deref(),
            ),
        }
    }

    /// The next readable image from the cursor on; `None` at the end of an unlooped folder.
    fn next_readable(&mut self) -> Result<Option<CameraFrame>, SourceError> {
        let count = self.paths.len();
        for _ in 0..count {
            if !self.looped && self.cursor >= count {
                break;
            }
            let index = self.cursor % count;
            self.cursor = if self.looped {
                index + 1
            } else {
                self.cursor + 1
            };
            if self.unreadable[index] {
                continue;
            }
            let frame = match self.cache[index].clone() {
                Some(frame) => frame,
                None => match self.decode(index) {
                    Ok(frame) => {
                        let bytes = frame.frame.image.as_raw().len();
                        if self.looped && self.cached_bytes + bytes <= self.budget_bytes {
                            self.cached_bytes += bytes;
                            self.cache[index] = Some(frame.clone());
                        }
                        frame
                    }
                    Err(error) => {
                        tracing::warn!(%error, "skipping image");
                        self.unreadable[index] = true;
                        self.skipped.push(error);
                        continue;
                    }
                },
            };
            // Decode the next image meanwhile, unless it is cached, known unreadable or past
            // the end of an unlooped folder.
            let next = index + 1;
            if self.looped || next < count {
                let next = next % count;
                if self.cache[next].is_none() && !self.unreadable[next] && self.ahead.is_none() {
                    self.ahead = Some((next, self.decode_ahead(next)));
                }
            }
            self.given += 1;
            return Ok(Some(frame));
        }
        if !self.looped && self.cursor >= count && self.given > 0 {
            return Ok(None);
        }
        Err(SourceError::Failed {
            source_name: self.name(),
            reason: format!("no readable image in {}", self.dir.display()),
        })
    }
}

impl FrameSource for FolderFrames {
    fn name(&self) -> String {
        format!("folder:{}", self.dir.display())
    }

    fn pacing(&self) -> Pacing {
        Pacing::Publisher
    }

    fn start(&mut self) -> Result<(), SourceError> {
        Ok(())
    }

    fn next_frame(&mut self, _timeout: Duration) -> Result<Next, SourceError> {
        Ok(match self.next_readable()? {
            Some(frame) => Next::Frame(Box::new(frame)),
            None => Next::Finished,
        })
    }

    fn repeats_frames(&self) -> bool {
        self.looped
    }

    fn take_skipped(&mut self) -> Vec<SourceError> {
        std::mem::take(&mut self.skipped)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use conesight_core::{Camera, Extrinsics};

    /// A folder of `good` small PNGs named 0.png, 1.png, ... and one file that is not an image.
    fn folder(name: &str, good: usize) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("conesight-sources-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        for i in 0..good {
            image::RgbImage::from_pixel(8, 6, image::Rgb([i as u8, 0, 0]))
                .save(dir.join(format!("{i}.png")))
                .unwrap();
        }
        std::fs::write(dir.join(format!("{good}.png")), b"not a png").unwrap();
        dir
    }

    fn open(dir: &Path, cache_mb: usize, looped: bool) -> FolderFrames {
        let calibration = Calibration {
            camera: Camera::pinhole(8, 6, 10.0),
            extrinsics: Extrinsics::paper_default(),
        };
        FolderFrames::new(dir, calibration, None, cache_mb, looped).unwrap()
    }

    fn next(frames: &mut FolderFrames) -> Result<CameraFrame, SourceError> {
        match frames.next_frame(Duration::ZERO)? {
            Next::Frame(frame) => Ok(*frame),
            other => panic!("a folder always has a frame: {other:?}"),
        }
    }

    #[test]
    fn folder_frames_loop_skip_unreadable_files_and_cache_within_budget() {
        let dir = folder("loop", 3);
        let mut frames = open(&dir, 1, true);
        assert_eq!(frames.len(), 4);
        assert_eq!(frames.cached(), 0, "nothing is decoded up front");
        let mut seen = Vec::new();
        for _ in 0..8 {
            let frame = next(&mut frames).unwrap();
            seen.push(frame.frame.index);
            assert_eq!(
                frame.frame.image.get_pixel(0, 0)[0] as u64,
                frame.frame.index
            );
        }
        // File 3 is broken: skipped on every loop.
        assert_eq!(seen, vec![0, 1, 2, 0, 1, 2, 0, 1]);
        assert_eq!(frames.cached(), 3);
        assert!(frames.repeats_frames());

        // A budget of 0 keeps nothing: every loop decodes again (memory stays bounded).
        let mut uncached = open(&dir, 0, true);
        for _ in 0..6 {
            assert!(next(&mut uncached).is_ok());
        }
        assert_eq!(uncached.cached(), 0);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Issue 40: JPEGs cut in half, cut to their headers and with stray bytes in their scan
    /// are never given as frames (they used to come out partly grey); each is reported once
    /// with its kind, naming the file, and the whole ones around them are given.
    #[test]
    fn truncated_and_corrupt_jpegs_in_a_folder_are_skipped_and_reported() {
        let dir =
            std::env::temp_dir().join(format!("conesight-sources-jpeg-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let mut jpeg = Vec::new();
        let noise = image::RgbImage::from_fn(8, 6, |x, y| {
            image::Rgb([(x * 31) as u8, (y * 40) as u8, 90])
        });
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 90)
            .encode_image(&noise)
            .unwrap();
        let scan = jpeg.windows(2).position(|w| w == [0xff, 0xda]).unwrap();
        let mut stray = jpeg.clone();
        // Halfway through the entropy-coded data (after the 14-byte SOS segment, before EOI).
        let inside = scan + 14 + (jpeg.len() - scan - 16) / 2;
        stray[inside] = 0xff;
        stray[inside + 1] = 0x42;
        std::fs::write(dir.join("0.jpg"), &jpeg).unwrap();
        std::fs::write(dir.join("1-half.jpg"), &jpeg[..jpeg.len() / 2]).unwrap();
        std::fs::write(dir.join("2-headers.jpg"), &jpeg[..scan]).unwrap();
        std::fs::write(dir.join("3-stray.jpg"), &stray).unwrap();
        std::fs::write(dir.join("4.jpg"), &jpeg).unwrap();
        let mut frames = open(&dir, 1, true);
        let given: Vec<u64> = (0..4)
            .map(|_| next(&mut frames).unwrap().frame.index)
            .collect();
        assert_eq!(given, vec![0, 4, 0, 4]);
        let skipped = frames.take_skipped();
        let kinds: Vec<&str> = skipped.iter().map(SourceError::kind).collect();
        assert_eq!(
            kinds,
            vec!["image_truncated", "image_truncated", "image_corrupt"],
            "{skipped:?}"
        );
        for (error, file) in skipped
            .iter()
            .zip(["1-half.jpg", "2-headers.jpg", "3-stray.jpg"])
        {
            assert!(error.to_string().contains(file), "{error}");
        }
        assert!(frames.take_skipped().is_empty(), "reported once");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Without `looped` the folder is given once, then the source is finished (it used to loop
    /// for ever, so `run` on a team's folder never ended); nothing is kept for a next loop.
    #[test]
    fn an_unlooped_folder_is_finished_after_its_last_image() {
        let dir = folder("once", 3);
        let mut frames = open(&dir, 1, false);
        let seen: Vec<u64> = (0..3)
            .map(|_| next(&mut frames).unwrap().frame.index)
            .collect();
        assert_eq!(seen, vec![0, 1, 2]);
        for _ in 0..2 {
            assert!(matches!(
                frames.next_frame(Duration::ZERO).unwrap(),
                Next::Finished
            ));
        }
        assert_eq!(frames.cached(), 0);
        assert!(!frames.repeats_frames());
        // A folder of unreadable files alone is still an error, not an end.
        let bad = folder("once-bad", 0);
        let mut frames = open(&bad, 1, false);
        assert!(frames.next_frame(Duration::ZERO).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
        std::fs::remove_dir_all(&bad).unwrap();
    }

    /// A calibration of another size is refused when the folder is opened, naming the image,
    /// both sizes and the fix (it used to be found frame by frame, and retried for ever).
    #[test]
    fn a_folder_of_another_size_than_the_calibration_is_refused_at_open() {
        let dir = folder("size", 1);
        let calibration = Calibration {
            camera: Camera::pinhole(16, 12, 20.0),
            extrinsics: Extrinsics::paper_default(),
        };
        let error = FolderFrames::new(&dir, calibration, None, 1, false)
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("0.png")
                && error.contains("8x6 px")
                && error.contains("16x12")
                && error.contains("pass the calibration of the camera that took it"),
            "{error}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn empty_or_unreadable_folders_are_clear_errors() {
        let dir = folder("bad", 0);
        let mut frames = open(&dir, 1, true);
        let error = next(&mut frames).unwrap_err().to_string();
        assert!(error.contains("no readable image"), "{error}");
        std::fs::remove_file(dir.join("0.png")).unwrap();
        let calibration = Calibration {
            camera: Camera::pinhole(8, 6, 10.0),
            extrinsics: Extrinsics::paper_default(),
        };
        let error = FolderFrames::new(&dir, calibration, None, 1, false)
            .unwrap_err()
            .to_string();
        assert!(error.contains("no image files"), "{error}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
