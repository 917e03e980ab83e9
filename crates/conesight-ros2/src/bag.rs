//! rosbag2 bags in MCAP: a folder with `<name>_0.mcap` (profile `ros2`, `ros2msg` schemas,
//! `cdr` messages) and `metadata.yaml` (rosbag2 format version 5), as `ros2 bag record -s mcap`
//! writes them, so `ros2 bag play`, `ros2 bag info`, rosbags and Foxglove's ROS 2 panels read
//! them.
//!
//! [`BagWriter::write_bus`] takes the bus's protobuf messages and writes, per camera `C`:
//! - `/conesight/C/image_raw` (`sensor_msgs/msg/Image`) for raw frames,
//!   `/conesight/C/image_raw/compressed` (`sensor_msgs/msg/CompressedImage`) for JPEG ones;
//! - `/conesight/C/camera_info` (`sensor_msgs/msg/CameraInfo`);
//! - `/conesight/C/cones` (`conesight_msgs/msg/ConeArray`), each cone with its keypoints from
//!   the same frame's keypoints message when it was recorded;
//! - `/conesight/C/cone_markers` (`visualization_msgs/msg/MarkerArray`): the cones for RViz.
//!
//! Detections and keypoints have no ROS 2 type of their own here: they are counted as skipped.

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use conesight_proto::{ConeKeypoints, Message, pb};
use serde::Serialize;

use crate::Ros2Error;
use crate::convert::{RosImage, camera_info, cone_array, cone_markers, ros_image};
use crate::msg::{
    CameraInfo, CompressedImage, ConeArray, Image, MarkerArray, RosMessage, definition,
};

/// Keypoints messages kept per camera to give the cones of their frame their keypoints.
const KEYPOINTS_KEPT: usize = 64;

/// The topic of `camera`'s `what` (`image_raw`, `camera_info`, `cones`).
pub fn topic(camera: &str, what: &str) -> String {
    format!("/conesight/{camera}/{what}")
}

struct Channel {
    id: u16,
    type_name: &'static str,
    count: u64,
}

/// A rosbag2 bag being written (see the module docs).
pub struct BagWriter {
    dir: PathBuf,
    file_name: String,
    writer: mcap::Writer<BufWriter<File>>,
    schemas: HashMap<&'static str, u16>,
    channels: BTreeMap<String, Channel>,
    sequence: u32,
    first_ns: Option<u64>,
    last_ns: u64,
    messages: u64,
    /// Bus messages with no ROS 2 counterpart (detections, keypoints).
    pub skipped: u64,
    keypoints: HashMap<String, VecDeque<(u64, Vec<ConeKeypoints>)>>,
}

impl BagWriter {
    /// Creates the bag folder `dir` (it must not exist yet) and its MCAP file.
    pub fn create(dir: &Path) -> Result<Self, Ros2Error> {
        let error = |reason: String| Ros2Error::Bag {
            path: dir.to_path_buf(),
            reason,
        };
        if dir.exists() {
            return Err(error(
                "exists already: a bag is a new folder (remove it or choose another --out)"
                    .to_owned(),
            ));
        }
        std::fs::create_dir_all(dir).map_err(|e| error(e.to_string()))?;
        let name = dir
            .file_name()
            .map_or_else(|| "bag".to_owned(), |n| n.to_string_lossy().into_owned());
        let file_name = format!("{name}_0.mcap");
        let file = File::create(dir.join(&file_name)).map_err(|e| error(e.to_string()))?;
        let writer = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .profile("ros2")
            .library(concat!("conesight-ros2 ", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::new(file))
            .map_err(|e| error(e.to_string()))?;
        Ok(Self {
            dir: dir.to_path_buf(),
            file_name,
            writer,
            schemas: HashMap::new(),
            channels: BTreeMap::new(),
            sequence: 0,
            first_ns: None,
            last_ns: 0,
            messages: 0,
            skipped: 0,
            keypoints: HashMap::new(),
        })
    }

    fn mcap_error(&self, error: &mcap::McapError) -> Ros2Error {
        Ros2Error::Bag {
            path: self.dir.join(&self.file_name),
            reason: error.to_string(),
        }
    }

    /// Writes `message` on `topic`, received at `log_time_ns` and stamped `publish_time_ns`.
    pub fn write<M: RosMessage>(
        &mut self,
        topic: &str,
        log_time_ns: u64,
        publish_time_ns: u64,
        message: &M,
    ) -> Result<(), Ros2Error> {
        let data = crate::to_cdr(message)?;
        self.write_cdr::<M>(topic, log_time_ns, publish_time_ns, &data)
    }

    /// Writes the CDR payload `data` of an `M` on `topic` as it is (not checked).
    pub fn write_cdr<M: RosMessage>(
        &mut self,
        topic: &str,
        log_time_ns: u64,
        publish_time_ns: u64,
        data: &[u8],
    ) -> Result<(), Ros2Error> {
        let id = match self.channels.get(topic) {
            Some(channel) => channel.id,
            None => {
                let schema = match self.schemas.get(M::TYPE) {
                    Some(id) => *id,
                    None => {
                        let id = self
                            .writer
                            .add_schema(M::TYPE, "ros2msg", definition::<M>().as_bytes())
                            .map_err(|e| self.mcap_error(&e))?;
                        self.schemas.insert(M::TYPE, id);
                        id
                    }
                };
                let id = self
                    .writer
                    .add_channel(schema, topic, "cdr", &BTreeMap::new())
                    .map_err(|e| self.mcap_error(&e))?;
                self.channels.insert(
                    topic.to_owned(),
                    Channel {
                        id,
                        type_name: M::TYPE,
                        count: 0,
                    },
                );
                id
            }
        };
        let header = mcap::records::MessageHeader {
            channel_id: id,
            sequence: self.sequence,
            log_time: log_time_ns,
            publish_time: publish_time_ns,
        };
        self.sequence = self.sequence.wrapping_add(1);
        self.writer
            .write_to_known_channel(&header, data)
            .map_err(|e| self.mcap_error(&e))?;
        if let Some(channel) = self.channels.get_mut(topic) {
            channel.count += 1;
        }
        self.first_ns = Some(self.first_ns.map_or(log_time_ns, |t| t.min(log_time_ns)));
        self.last_ns = self.last_ns.max(log_time_ns);
        self.messages += 1;
        Ok(())
    }

    /// Writes a bus message of `stream` (`frame`, `camera_info`, `cones`; `keypoints` are kept
    /// for the cones of their frame; others are skipped) given as its protobuf bytes. False
    /// when nothing was written for it.
    pub fn write_bus(
        &mut self,
        stream: &str,
        log_time_ns: u64,
        data: &[u8],
    ) -> Result<bool, Ros2Error> {
        let invalid =
            |type_name: &'static str, reason: String| Ros2Error::Invalid { type_name, reason };
        match stream {
            "frame" => {
                let frame = pb::ImageFrame::decode(data)
                    .map_err(|e| invalid("conesight.v1.ImageFrame", e.to_string()))?;
                let (camera, publish) = camera_and_publish(frame.header.as_ref(), log_time_ns);
                match ros_image(&frame)? {
                    RosImage::Raw(image) => {
                        self.write::<Image>(
                            &topic(&camera, "image_raw"),
                            log_time_ns,
                            publish,
                            &image,
                        )?;
                    }
                    RosImage::Compressed(image) => self.write::<CompressedImage>(
                        &topic(&camera, "image_raw/compressed"),
                        log_time_ns,
                        publish,
                        &image,
                    )?,
                }
            }
            "camera_info" => {
                let info = pb::CameraInfo::decode(data)
                    .map_err(|e| invalid("conesight.v1.CameraInfo", e.to_string()))?;
                let header = conesight_proto::require_header(&info.header)
                    .map_err(|e| invalid("conesight.v1.CameraInfo", e.to_string()))?
                    .clone();
                let (camera, _) = info
                    .to_core()
                    .map_err(|e| invalid("conesight.v1.CameraInfo", e.to_string()))?;
                let ros = camera_info(&header, &camera);
                self.write::<CameraInfo>(
                    &topic(&header.camera_id, "camera_info"),
                    log_time_ns,
                    header.publish_time_ns.max(1),
                    &ros,
                )?;
            }
            "keypoints" => {
                let message = pb::Keypoints::decode(data)
                    .map_err(|e| invalid("conesight.v1.Keypoints", e.to_string()))?;
                let header = message.header.clone().unwrap_or_default();
                let keypoints = message
                    .to_core()
                    .map_err(|e| invalid("conesight.v1.Keypoints", e.to_string()))?;
                let kept = self.keypoints.entry(header.camera_id).or_default();
                kept.push_back((header.frame_sequence, keypoints));
                while kept.len() > KEYPOINTS_KEPT {
                    kept.pop_front();
                }
                self.skipped += 1;
                return Ok(false);
            }
            "cones" => {
                let message = pb::Cones::decode(data)
                    .map_err(|e| invalid("conesight.v1.Cones", e.to_string()))?;
                let header = conesight_proto::require_header(&message.header)
                    .map_err(|e| invalid("conesight.v1.Cones", e.to_string()))?
                    .clone();
                let cones = message
                    .to_core()
                    .map_err(|e| invalid("conesight.v1.Cones", e.to_string()))?;
                let keypoints = self
                    .keypoints
                    .get(&header.camera_id)
                    .and_then(|kept| kept.iter().rev().find(|(s, _)| *s == header.frame_sequence))
                    .map(|(_, k)| k.as_slice())
                    .unwrap_or_default();
                let array = cone_array(&header, &cones, keypoints);
                let publish = header.publish_time_ns.max(1);
                self.write::<ConeArray>(
                    &topic(&header.camera_id, "cones"),
                    log_time_ns,
                    publish,
                    &array,
                )?;
                self.write::<MarkerArray>(
                    &topic(&header.camera_id, "cone_markers"),
                    log_time_ns,
                    publish,
                    &cone_markers(&array, &header.camera_id),
                )?;
            }
            _ => {
                self.skipped += 1;
                return Ok(false);
            }
        }
        Ok(true)
    }

    /// Finishes the MCAP file and writes `metadata.yaml`; returns the bag folder.
    pub fn finish(mut self) -> Result<PathBuf, Ros2Error> {
        self.writer.finish().map_err(|e| self.mcap_error(&e))?;
        let start = self.first_ns.unwrap_or(0);
        let duration = self.last_ns.saturating_sub(start);
        let metadata = MetadataFile {
            rosbag2_bagfile_information: Metadata {
                version: 5,
                storage_identifier: "mcap",
                duration: Nanoseconds {
                    nanoseconds: duration,
                },
                starting_time: SinceEpoch {
                    nanoseconds_since_epoch: start,
                },
                message_count: self.messages,
                topics_with_message_count: self
                    .channels
                    .iter()
                    .map(|(name, channel)| TopicCount {
                        topic_metadata: TopicMetadata {
                            name: name.clone(),
                            r#type: channel.type_name,
                            serialization_format: "cdr",
                            offered_qos_profiles: String::new(),
                        },
                        message_count: channel.count,
                    })
                    .collect(),
                compression_format: "",
                compression_mode: "",
                relative_file_paths: vec![self.file_name.clone()],
                files: vec![FileInfo {
                    path: self.file_name.clone(),
                    starting_time: SinceEpoch {
                        nanoseconds_since_epoch: start,
                    },
                    duration: Nanoseconds {
                        nanoseconds: duration,
                    },
                    message_count: self.messages,
                }],
            },
        };
        let path = self.dir.join("metadata.yaml");
        let yaml = serde_yaml_ng::to_string(&metadata).map_err(|e| Ros2Error::Bag {
            path: path.clone(),
            reason: e.to_string(),
        })?;
        std::fs::write(&path, yaml).map_err(|e| Ros2Error::Bag {
            path: path.clone(),
            reason: e.to_string(),
        })?;
        Ok(self.dir)
    }
}

/// The camera of a frame's header and its publish time (the log time when absent).
fn camera_and_publish(header: Option<&pb::Header>, log_time_ns: u64) -> (String, u64) {
    header.map_or_else(
        || ("front".to_owned(), log_time_ns),
        |h| (h.camera_id.clone(), h.publish_time_ns.max(1)),
    )
}

#[derive(Serialize)]
struct MetadataFile {
    rosbag2_bagfile_information: Metadata,
}

#[derive(Serialize)]
struct Metadata {
    version: u32,
    storage_identifier: &'static str,
    duration: Nanoseconds,
    starting_time: SinceEpoch,
    message_count: u64,
    topics_with_message_count: Vec<TopicCount>,
    compression_format: &'static str,
    compression_mode: &'static str,
    relative_file_paths: Vec<String>,
    files: Vec<FileInfo>,
}

#[derive(Serialize)]
struct Nanoseconds {
    nanoseconds: u64,
}

#[derive(Serialize)]
struct SinceEpoch {
    nanoseconds_since_epoch: u64,
}

#[derive(Serialize)]
struct TopicCount {
    topic_metadata: TopicMetadata,
    message_count: u64,
}

#[derive(Serialize)]
struct TopicMetadata {
    name: String,
    r#type: &'static str,
    serialization_format: &'static str,
    offered_qos_profiles: String,
}

#[derive(Serialize)]
struct FileInfo {
    path: String,
    starting_time: SinceEpoch,
    duration: Nanoseconds,
    message_count: u64,
}

/// The MCAP files of a bag folder (from its `metadata.yaml`, else every `*.mcap` in it, in
/// name order).
pub fn bag_files(dir: &Path) -> Result<Vec<PathBuf>, Ros2Error> {
    let error = |reason: String| Ros2Error::Bag {
        path: dir.to_path_buf(),
        reason,
    };
    #[derive(serde::Deserialize)]
    struct Info {
        relative_file_paths: Vec<String>,
    }
    #[derive(serde::Deserialize)]
    struct File {
        rosbag2_bagfile_information: Info,
    }
    let metadata = dir.join("metadata.yaml");
    if let Ok(text) = std::fs::read_to_string(&metadata) {
        let file: File =
            serde_yaml_ng::from_str(&text).map_err(|e| error(format!("metadata.yaml: {e}")))?;
        return Ok(file
            .rosbag2_bagfile_information
            .relative_file_paths
            .iter()
            .map(|p| dir.join(Path::new(p).file_name().unwrap_or_default()))
            .collect());
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| error(e.to_string()))?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(error("no metadata.yaml and no .mcap file in it".to_owned()));
    }
    Ok(files)
}
