//! [`SourceSpec`]: the `--source` grammar, `synthetic | folder[:DIR] | video:PATH |
//! gst:PIPELINE`.

use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;

use crate::error::SourceError;

/// Where frames come from, as written after `--source`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SourceSpec {
    /// `synthetic`: the renderer driving a track, with exact ground truth.
    Synthetic,
    /// `folder:DIR` (or `folder` with the directory given by `--images`): image files in name
    /// order, looped.
    Folder(Option<PathBuf>),
    /// `video:PATH`: a video file GStreamer can decode (`filesrc ! decodebin`), played at its
    /// own rate.
    Video(PathBuf),
    /// `gst:PIPELINE`: a GStreamer pipeline description up to the last element (a camera:
    /// `v4l2src`, `aravissrc`, `nvarguscamerasrc ! nvvidconv`, `rtspsrc ! decodebin`, ...);
    /// conesight appends `videoconvert ! video/x-raw,format=RGB ! appsink`.
    Gst(String),
    /// A ROS 2 image topic over rmw_zenoh (`ros2:/cam/image_raw`).
    Ros2(String),
}

/// The forms `--source` takes, for error messages and `--help`.
pub const SOURCE_GRAMMAR: &str = "synthetic | folder:DIR | video:PATH | gst:PIPELINE | ros2:TOPIC";

impl SourceSpec {
    /// True for the sources that need a calibration file (every one but `synthetic`).
    pub fn needs_calibration(&self) -> bool {
        !matches!(self, Self::Synthetic | Self::Ros2(_))
    }

    /// True for GStreamer sources (a pipeline or a video file).
    pub fn is_gstreamer(&self) -> bool {
        matches!(self, Self::Video(_) | Self::Gst(_))
    }

    /// The short name of the kind (`synthetic`, `folder`, `video`, `gst`).
    pub fn kind(&self) -> &'static str {
        match self {
            Self::Synthetic => "synthetic",
            Self::Folder(_) => "folder",
            Self::Video(_) => "video",
            Self::Gst(_) => "gst",
            Self::Ros2(_) => "ros2",
        }
    }
}

impl FromStr for SourceSpec {
    type Err = SourceError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let invalid = |reason: &str| SourceError::InvalidSpec {
            spec: text.to_owned(),
            reason: reason.to_owned(),
        };
        let (kind, rest) = match text.split_once(':') {
            Some((kind, rest)) => (kind.trim(), Some(rest)),
            None => (text.trim(), None),
        };
        match (kind, rest) {
            ("synthetic", None) => Ok(Self::Synthetic),
            ("synthetic", Some(_)) => Err(invalid("`synthetic` takes no argument")),
            ("folder", None) => Ok(Self::Folder(None)),
            ("folder", Some("")) => Err(invalid("`folder:` needs a directory")),
            ("folder", Some(dir)) => Ok(Self::Folder(Some(PathBuf::from(dir)))),
            ("video", Some(path)) if !path.trim().is_empty() => {
                Ok(Self::Video(PathBuf::from(path)))
            }
            ("video", _) => Err(invalid("`video:` needs a file path")),
            ("gst", Some(pipeline)) if !pipeline.trim().is_empty() => {
                let pipeline = pipeline.trim();
                if pipeline.split('!').any(|element| element.trim().is_empty()) {
                    return Err(invalid("an empty element between `!`s"));
                }
                if pipeline
                    .split('!')
                    .any(|element| element.split_whitespace().next() == Some("appsink"))
                {
                    return Err(invalid(
                        "leave out the appsink: conesight appends `videoconvert ! \
                         video/x-raw,format=RGB ! appsink` itself",
                    ));
                }
                Ok(Self::Gst(pipeline.to_owned()))
            }
            ("gst", _) => Err(invalid("`gst:` needs a pipeline, e.g. `gst:v4l2src`")),
            ("ros2", Some(topic)) if !topic.trim().trim_matches('/').is_empty() => {
                Ok(Self::Ros2(format!("/{}", topic.trim().trim_matches('/'))))
            }
            ("ros2", _) => Err(invalid(
                "`ros2:` needs an image topic, e.g. `ros2:/camera/image_raw`",
            )),
            _ => Err(invalid("unknown kind")),
        }
    }
}

impl fmt::Display for SourceSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Synthetic => write!(f, "synthetic"),
            Self::Folder(None) => write!(f, "folder"),
            Self::Folder(Some(dir)) => write!(f, "folder:{}", dir.display()),
            Self::Video(path) => write!(f, "video:{}", path.display()),
            Self::Gst(pipeline) => write!(f, "gst:{pipeline}"),
            Self::Ros2(topic) => write!(f, "ros2:{topic}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<SourceSpec, String> {
        text.parse::<SourceSpec>().map_err(|e| e.to_string())
    }

    #[test]
    fn every_kind_parses_and_prints_back() {
        for (text, spec) in [
            ("synthetic", SourceSpec::Synthetic),
            ("folder", SourceSpec::Folder(None)),
            (
                "folder:/data/drive 1",
                SourceSpec::Folder(Some("/data/drive 1".into())),
            ),
            ("video:drive.avi", SourceSpec::Video("drive.avi".into())),
            (
                "ros2:/cam/image_raw",
                SourceSpec::Ros2("/cam/image_raw".into()),
            ),
            // A path with a colon keeps it: only the first one separates the kind.
            ("video:C:/x.mp4", SourceSpec::Video("C:/x.mp4".into())),
            (
                "gst:v4l2src device=/dev/video0 ! video/x-raw,width=1920,height=1200",
                SourceSpec::Gst(
                    "v4l2src device=/dev/video0 ! video/x-raw,width=1920,height=1200".into(),
                ),
            ),
        ] {
            assert_eq!(parse(text).unwrap(), spec, "{text}");
            assert_eq!(parse(&spec.to_string()).unwrap(), spec);
        }
        assert_eq!(
            parse("gst:  videotestsrc num-buffers=3  ").unwrap(),
            SourceSpec::Gst("videotestsrc num-buffers=3".into())
        );
    }

    #[test]
    fn bad_specs_say_what_is_wrong() {
        for (text, needle) in [
            ("camera", "unknown kind"),
            ("", "unknown kind"),
            ("synthetic:7", "takes no argument"),
            ("folder:", "needs a directory"),
            ("video", "needs a file path"),
            ("video:", "needs a file path"),
            ("gst", "needs a pipeline"),
            ("gst:  ", "needs a pipeline"),
            ("gst:videotestsrc ! ! videoconvert", "empty element"),
            ("gst:videotestsrc !", "empty element"),
            ("gst:videotestsrc ! appsink name=x", "leave out the appsink"),
        ] {
            let error = parse(text).unwrap_err();
            assert!(error.contains(needle), "{text:?}: {error}");
            assert!(error.contains(SOURCE_GRAMMAR), "{text:?}: {error}");
        }
    }

    #[test]
    fn only_synthetic_needs_no_calibration() {
        assert!(!SourceSpec::Synthetic.needs_calibration());
        for text in ["folder", "video:a.avi", "gst:videotestsrc"] {
            assert!(parse(text).unwrap().needs_calibration(), "{text}");
        }
        assert!(parse("gst:videotestsrc").unwrap().is_gstreamer());
        assert!(!SourceSpec::Folder(None).is_gstreamer());
    }
}
