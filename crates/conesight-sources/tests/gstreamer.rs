//! The GStreamer sources on real pipelines (no mocks): a live `videotestsrc` at an odd frame size (RGB
//! rows padded to 4 bytes), its end of stream, time stamps from the buffers, a video file made
//! here (`jpegenc ! avimux`, from the Debian plugins `scripts/setup.sh` installs) played to its
//! end and looped, and the errors a user meets first.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use conesight_core::{Camera, Extrinsics};
use conesight_sources::{
    Calibration, CameraFrame, FrameSource, GstSource, Next, SourceError, check_size,
};
use gstreamer as gst;
use gstreamer::prelude::*;

/// A pinhole camera of `width` x `height`.
fn calibration(width: u32, height: u32) -> Calibration {
    let mut camera = Camera::paper_default();
    camera.width_px = width;
    camera.height_px = height;
    camera.cx_px = f64::from(width) / 2.0;
    camera.cy_px = f64::from(height) / 2.0;
    Calibration {
        camera,
        extrinsics: Extrinsics::paper_default(),
    }
}

/// Frames until the source ends (or `limit` frames, or 10 s): the frames and what ended it.
fn drain(source: &mut dyn FrameSource, limit: usize) -> (Vec<CameraFrame>, Option<SourceError>) {
    let mut frames = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(10);
    while frames.len() < limit && Instant::now() < deadline {
        match source.next_frame(Duration::from_millis(100)) {
            Ok(Next::Frame(frame)) => frames.push(*frame),
            Ok(Next::Pending) => {}
            Ok(Next::Finished) => return (frames, None),
            Err(error) => return (frames, Some(error)),
        }
    }
    (frames, None)
}

#[test]
fn videotestsrc_frames_have_their_pixels_at_an_odd_width_and_buffer_stamps() {
    // 321 px: an RGB row is 963 bytes, padded to a stride of 964.
    let mut source = GstSource::pipeline(
        "videotestsrc is-live=true num-buffers=6 pattern=solid-color foreground-color=0xff102030 ! \
         video/x-raw,format=RGB,width=321,height=241,framerate=30/1",
        calibration(321, 241),
    )
    .unwrap();
    assert!(
        source
            .description()
            .ends_with("appsink name=conesight_sink max-buffers=1 drop=true sync=false")
    );
    let started_ns = conesight_proto::now_ns();
    source.start().unwrap();
    let (frames, end) = drain(&mut source, 100);
    assert_eq!(
        frames.len(),
        6,
        "every buffer of a source played in real time"
    );
    for (i, frame) in frames.iter().enumerate() {
        assert_eq!(frame.frame.index, i as u64);
        assert_eq!(frame.frame.image.dimensions(), (321, 241));
        check_size("test", &frame.frame).unwrap();
        let wrong: Vec<_> = frame
            .frame
            .image
            .enumerate_pixels()
            .filter(|(_, _, p)| p.0 != [0x10, 0x20, 0x30])
            .take(3)
            .collect();
        assert!(
            wrong.is_empty(),
            "frame {i}: pixels off the solid colour: {wrong:?}"
        );
    }
    // Stamped from the buffers' PTS at 30 frames/s (1/30 s apart, up to scheduling jitter),
    // on the wall clock.
    let stamps: Vec<u64> = frames.iter().map(|f| f.acquisition_ns.unwrap()).collect();
    assert!(stamps[0] >= started_ns && stamps[0] < started_ns + 2_000_000_000);
    for pair in stamps.windows(2) {
        let step_ms = (pair[1] as f64 - pair[0] as f64) / 1e6;
        assert!(
            (20.0..50.0).contains(&step_ms),
            "frames {step_ms:.1} ms apart: {stamps:?}"
        );
    }
    // num-buffers reached: end of stream, the camera went away.
    let end = end.expect("the pipeline ends");
    assert!(matches!(end, SourceError::Ended { .. }), "{end}");
    assert_eq!(end.kind(), "source_ended");
    // It can be started again (the camera service's restart).
    source.stop();
    source.start().unwrap();
    let (again, _) = drain(&mut source, 2);
    assert_eq!(again.len(), 2);
}

#[test]
fn other_formats_are_converted_to_rgb() {
    let mut source = GstSource::pipeline(
        "videotestsrc is-live=true num-buffers=2 pattern=white ! video/x-raw,format=I420,width=64,height=48",
        calibration(64, 48),
    )
    .unwrap();
    source.start().unwrap();
    let (frames, _) = drain(&mut source, 2);
    assert_eq!(frames.len(), 2);
    let pixel = frames[0].frame.image.get_pixel(10, 10).0;
    assert!(pixel.iter().all(|&c| c >= 250), "white: {pixel:?}");
}

/// Writes a `frames`-frame MJPEG AVI of `width` x `height` at 30 frames/s.
fn write_video(path: &Path, frames: u32, width: u32, height: u32) {
    gst::init().unwrap();
    let pipeline = gst::parse::launch(&format!(
        "videotestsrc num-buffers={frames} ! video/x-raw,width={width},height={height},framerate=30/1 ! \
         jpegenc ! avimux ! filesink name=out"
    ))
    .unwrap()
    .downcast::<gst::Pipeline>()
    .unwrap();
    pipeline
        .by_name("out")
        .unwrap()
        .set_property("location", path.to_str().unwrap());
    pipeline.set_state(gst::State::Playing).unwrap();
    let bus = pipeline.bus().unwrap();
    let message = bus
        .timed_pop_filtered(
            gst::ClockTime::from_seconds(30),
            &[gst::MessageType::Eos, gst::MessageType::Error],
        )
        .unwrap();
    assert!(
        matches!(message.view(), gst::MessageView::Eos(_)),
        "{message:?}"
    );
    pipeline.set_state(gst::State::Null).unwrap();
}

fn temp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("conesight-sources-{name}-{}", std::process::id()))
}

#[test]
fn a_video_file_plays_to_its_end_or_loops() {
    let path = temp("video.avi");
    write_video(&path, 10, 160, 120);
    let mut once = GstSource::video(&path, calibration(160, 120), false).unwrap();
    once.start().unwrap();
    let (frames, error) = drain(&mut once, 100);
    assert!(error.is_none(), "{error:?}");
    assert_eq!(frames.len(), 10, "every frame of the file, then finished");
    assert_eq!(frames[0].frame.image.dimensions(), (160, 120));

    let mut looped = GstSource::video(&path, calibration(160, 120), true).unwrap();
    looped.start().unwrap();
    let (frames, error) = drain(&mut looped, 25);
    assert!(error.is_none(), "{error:?}");
    assert_eq!(frames.len(), 25, "looped past its 10 frames");
    std::fs::remove_file(&path).unwrap();
}

#[test]
fn first_errors_name_what_is_wrong() {
    let error = GstSource::pipeline("nosuchcamerasrc", calibration(8, 8)).unwrap_err();
    assert!(error.to_string().contains("nosuchcamerasrc"), "{error}");
    let error = GstSource::video(
        Path::new("/nonexistent/drive.avi"),
        calibration(8, 8),
        false,
    )
    .unwrap_err();
    assert!(
        error.to_string().contains("/nonexistent/drive.avi"),
        "{error}"
    );

    // A frame of another size than the calibration's names both.
    let mut source = GstSource::pipeline(
        "videotestsrc is-live=true num-buffers=1 ! video/x-raw,width=64,height=48",
        calibration(1920, 1200),
    )
    .unwrap();
    source.start().unwrap();
    let (frames, _) = drain(&mut source, 1);
    let error = check_size("gst:videotestsrc", &frames[0].frame)
        .unwrap_err()
        .to_string();
    assert!(
        error.contains("64x48") && error.contains("1920x1200"),
        "{error}"
    );

    // A source that fails while running (a file that is not a video): reported as failed.
    let path = temp("not-a-video.avi");
    std::fs::write(&path, b"not a video at all").unwrap();
    let mut broken = GstSource::video(&path, calibration(8, 8), false).unwrap();
    let error = broken
        .start()
        .err()
        .or_else(|| drain(&mut broken, 1).1)
        .expect("a failure");
    assert_eq!(error.kind(), "source_failed", "{error}");
    std::fs::remove_file(&path).unwrap();
}
