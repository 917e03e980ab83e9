//! The model card: layout, input size, class names and decoding thresholds. It comes from
//! (first found wins) the caller, `NAME.card.json` beside `NAME.onnx` (written by conesight's
//! exporter), or the ONNX file's own metadata: conesight's exporter writes
//! `conesight_layout`, `names`, `imgsz`; **Ultralytics** exports write `names`, `imgsz`,
//! `task` and `end2end` ([`ModelCard::from_metadata`]), so a user's `best.onnx` runs as it
//! comes, with no card.
//!
//! Only the fields below are read; the exporter's other fields (metrics, sha256) are ignored.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::DetectError;
use crate::thresholds::Thresholds;

/// How a model's input is made and its output laid out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Layout {
    /// conesight's detector: the whole frame area-resized into the input at its top-left
    /// corner ([`FrameInputParams`]); raw 0..255 RGB input.
    ConesightFrame,
    /// Ultralytics YOLO export: letterbox to the input size (grey 114 padding), RGB / 255.
    Ultralytics,
}

/// conesight's input size (the rule is in [`crate::preprocess`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct FrameInputParams {
    /// Network input width.
    pub input_width_px: u32,
    /// Network input height.
    pub input_height_px: u32,
}

impl Default for FrameInputParams {
    /// The shipped size: 960x608, so 1920x1200 frames are halved exactly.
    fn default() -> Self {
        Self {
            input_width_px: 960,
            input_height_px: 608,
        }
    }
}

/// The input tensor's description in the card.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InputSpec {
    /// `[1, 3, height, width]`.
    pub shape: [usize; 4],
}

/// What the runtime needs to know about a detector model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelCard {
    /// Input scheme and output layout.
    pub layout: Layout,
    /// The network input.
    pub input: InputSpec,
    /// The input size (required for [`Layout::ConesightFrame`]).
    #[serde(default)]
    pub frame_input: Option<FrameInputParams>,
    /// Class names in output order (conesight or FSOCO names; `unknown_cone` is skipped).
    pub class_names: Vec<String>,
    /// Decoding thresholds the model was evaluated with.
    #[serde(default)]
    pub thresholds: Option<Thresholds>,
    /// The NMS-free output `[1, N, 6]` (x_min, y_min, x_max, y_max, score, class) of
    /// Ultralytics' end-to-end models and `nms=True` exports, instead of `[1, 4 + classes, N]`.
    #[serde(default)]
    pub end2end: bool,
}

impl ModelCard {
    /// A card for an Ultralytics export with a `width x height` input (commonly 640x640) and
    /// its class names in output order, with default thresholds.
    pub fn ultralytics(width_px: usize, height_px: usize, class_names: &[&str]) -> Self {
        Self {
            layout: Layout::Ultralytics,
            input: InputSpec {
                shape: [1, 3, height_px, width_px],
            },
            frame_input: None,
            class_names: class_names.iter().map(|s| (*s).to_owned()).collect(),
            thresholds: None,
            end2end: false,
        }
    }

    /// The card path for a model: `NAME.card.json` beside `NAME.onnx`.
    pub fn path_for(model: &Path) -> PathBuf {
        model.with_extension("card.json")
    }

    /// Reads a card file.
    pub fn read(path: &Path) -> Result<Self, DetectError> {
        let text = std::fs::read_to_string(path).map_err(|e| DetectError::CardRead {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        serde_json::from_str(&text).map_err(|e| {
            let hint = if text.contains("conesight_band") {
                "a card of the retired horizon-band detector: re-export the model with \
                 `python -m conesight_train.detector.onnx_export`"
            } else {
                "not a valid JSON model card: fix it, or delete it when the ONNX file carries \
                 its own metadata (Ultralytics exports do)"
            };
            DetectError::CardRead {
                path: path.to_path_buf(),
                message: format!("{e} ({hint})"),
            }
        })
    }

    /// The card an ONNX file's metadata describes, or `None` when it carries none of the keys
    /// (see the module docs). `model` names the model in errors.
    pub fn from_metadata(
        metadata: &[(String, String)],
        model: &str,
    ) -> Result<Option<Self>, DetectError> {
        let get = |key: &str| {
            metadata
                .iter()
                .find(|(k, _)| k == key)
                .map(|(_, v)| v.trim())
        };
        let invalid = |problem: String| DetectError::CardInvalid {
            model: model.to_owned(),
            problem,
        };
        let (Some(names), Some(imgsz)) = (get("names"), get("imgsz")) else {
            return Ok(None);
        };
        if let Some(task) = get("task")
            && task != "detect"
        {
            return Err(invalid(format!(
                "the ONNX metadata says task `{task}`; conesight needs a detection model \
                 (`yolo train task=detect`, then `yolo export format=onnx`)"
            )));
        }
        let class_names = parse_python_names(names)
            .ok_or_else(|| invalid(format!("cannot read the metadata `names` = {names}")))?;
        let size = parse_int_list(imgsz)
            .ok_or_else(|| invalid(format!("cannot read the metadata `imgsz` = {imgsz}")))?;
        let (height, width) = match size.as_slice() {
            [h, w] => (*h, *w),
            [s] => (*s, *s),
            _ => {
                return Err(invalid(format!(
                    "metadata `imgsz` = {imgsz}: expected [h, w]"
                )));
            }
        };
        let conesight = get("conesight_layout") == Some("conesight_frame");
        let float = |key: &str| get(key).and_then(|v| v.parse::<f32>().ok());
        let thresholds = match (float("score_threshold"), float("nms_iou")) {
            (Some(score_threshold), Some(nms_iou)) => Some(Thresholds {
                score_threshold,
                nms_iou,
                max_detections: get("max_detections")
                    .and_then(|v| v.parse().ok())
                    .unwrap_or(Thresholds::default().max_detections),
            }),
            _ => None,
        };
        Ok(Some(Self {
            layout: if conesight {
                Layout::ConesightFrame
            } else {
                Layout::Ultralytics
            },
            input: InputSpec {
                shape: [1, 3, height, width],
            },
            frame_input: conesight.then_some(FrameInputParams {
                input_width_px: width as u32,
                input_height_px: height as u32,
            }),
            class_names,
            thresholds,
            // NMS-free heads (YOLOv10, YOLO26) say `end2end`; `yolo export nms=True` puts the
            // NMS in the graph and says so only in its export `args`. Both give [1, N, 6].
            end2end: matches!(get("end2end"), Some("True" | "true" | "1"))
                || get("args").is_some_and(|a| a.replace(' ', "").contains("'nms':True")),
        }))
    }

    /// Checks the fields against each other (`model` names the model in errors).
    pub fn validate(&self, model: &str) -> Result<(), DetectError> {
        let invalid = |problem: String| DetectError::CardInvalid {
            model: model.to_owned(),
            problem,
        };
        let [n, c, h, w] = self.input.shape;
        if n != 1 || c != 3 || h == 0 || w == 0 {
            return Err(invalid(format!(
                "input shape {:?} must be [1, 3, height, width]",
                self.input.shape
            )));
        }
        if self.class_names.is_empty() {
            return Err(invalid("class_names is empty".to_owned()));
        }
        if self.layout == Layout::ConesightFrame {
            let input = self.frame_input.ok_or_else(|| {
                invalid("layout conesight_frame needs a `frame_input` entry".to_owned())
            })?;
            if input.input_width_px as usize != w || input.input_height_px as usize != h {
                return Err(invalid(format!(
                    "frame_input {input:?} does not match the input shape {:?}",
                    self.input.shape
                )));
            }
        }
        Ok(())
    }
}

/// Ultralytics' `names` metadata, a Python dict literal `{0: 'blue_cone', 1: "it's"}` (or a
/// list `['a', 'b']`) -> the names in index order.
fn parse_python_names(text: &str) -> Option<Vec<String>> {
    let inner = text.trim();
    let dict = inner.starts_with('{');
    let inner = inner.strip_prefix(['{', '['])?.strip_suffix(['}', ']'])?;
    let mut entries: Vec<(usize, String)> = Vec::new();
    let mut chars = inner.chars().peekable();
    let mut index = 0usize;
    loop {
        while chars.peek().is_some_and(|c| c.is_whitespace() || *c == ',') {
            chars.next();
        }
        if chars.peek().is_none() {
            break;
        }
        if dict {
            let key: String = chars.by_ref().take_while(|c| *c != ':').collect();
            index = key.trim().parse().ok()?;
            while chars.peek().is_some_and(|c| c.is_whitespace()) {
                chars.next();
            }
        }
        let quote = chars.next().filter(|c| *c == '\'' || *c == '"')?;
        let mut name = String::new();
        loop {
            match chars.next()? {
                '\\' => name.push(chars.next()?),
                c if c == quote => break,
                c => name.push(c),
            }
        }
        entries.push((index, name));
        index += 1;
    }
    entries.sort_by_key(|(i, _)| *i);
    let in_order = entries.iter().enumerate().all(|(i, (k, _))| i == *k);
    (in_order && !entries.is_empty()).then(|| entries.into_iter().map(|(_, n)| n).collect())
}

/// `[640, 640]`, `(640, 640)` or `640` -> the integers.
fn parse_int_list(text: &str) -> Option<Vec<usize>> {
    text.trim()
        .trim_matches(['[', ']', '(', ')'])
        .split(',')
        .filter(|s| !s.trim().is_empty())
        .map(|s| s.trim().parse().ok())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn meta(pairs: &[(&str, &str)]) -> Vec<(String, String)> {
        pairs
            .iter()
            .map(|(k, v)| ((*k).to_owned(), (*v).to_owned()))
            .collect()
    }

    #[test]
    fn ultralytics_metadata_gives_names_size_and_output_layout() {
        let card = ModelCard::from_metadata(
            &meta(&[
                (
                    "names",
                    "{0: 'blue_cone', 1: 'large_orange_cone', 2: \"it's\"}",
                ),
                ("imgsz", "[384, 640]"),
                ("task", "detect"),
                ("end2end", "True"),
                ("stride", "32"),
            ]),
            "m",
        )
        .unwrap()
        .unwrap();
        assert_eq!(card.layout, Layout::Ultralytics);
        assert_eq!(card.input.shape, [1, 3, 384, 640]);
        assert_eq!(card.class_names, ["blue_cone", "large_orange_cone", "it's"]);
        assert!(card.end2end);
        assert!(card.thresholds.is_none());
        // `yolo export nms=True` of a YOLO11: end2end False, the NMS in the graph, said in args.
        let card = ModelCard::from_metadata(
            &meta(&[
                ("names", "{0: 'blue_cone'}"),
                ("imgsz", "[640, 640]"),
                ("end2end", "False"),
                ("args", "{'data': None, 'nms': True, 'dynamic': False}"),
            ]),
            "m",
        )
        .unwrap()
        .unwrap();
        assert!(card.end2end);
    }

    #[test]
    fn conesight_metadata_gives_the_frame_layout_and_thresholds() {
        let card = ModelCard::from_metadata(
            &meta(&[
                ("conesight_layout", "conesight_frame"),
                (
                    "names",
                    "{0: 'blue', 1: 'yellow', 2: 'orange', 3: 'large_orange'}",
                ),
                ("imgsz", "[608, 960]"),
                ("score_threshold", "0.3"),
                ("nms_iou", "0.5"),
            ]),
            "m",
        )
        .unwrap()
        .unwrap();
        assert_eq!(card.layout, Layout::ConesightFrame);
        assert_eq!(card.frame_input, Some(FrameInputParams::default()));
        assert_eq!(card.thresholds.unwrap().score_threshold, 0.3);
        card.validate("m").unwrap();
    }

    #[test]
    fn metadata_without_the_keys_or_of_another_task() {
        assert!(
            ModelCard::from_metadata(&meta(&[("stride", "32")]), "m")
                .unwrap()
                .is_none()
        );
        let err = ModelCard::from_metadata(
            &meta(&[
                ("names", "{0: 'a'}"),
                ("imgsz", "[64, 64]"),
                ("task", "segment"),
            ]),
            "m",
        )
        .unwrap_err();
        assert!(err.to_string().contains("task `segment`"), "{err}");
        let err = ModelCard::from_metadata(&meta(&[("names", "{0: a}"), ("imgsz", "[64]")]), "m")
            .unwrap_err();
        assert!(err.to_string().contains("`names`"), "{err}");
    }

    #[test]
    fn python_lists_and_gaps() {
        assert_eq!(
            parse_python_names("['a', 'b']").unwrap(),
            vec!["a".to_owned(), "b".to_owned()]
        );
        assert!(parse_python_names("{0: 'a', 2: 'c'}").is_none());
        assert_eq!(parse_int_list("640").unwrap(), vec![640]);
    }
}
