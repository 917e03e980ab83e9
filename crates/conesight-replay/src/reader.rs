//! Reading `conesight record` files: [`McapFile`] streams one file's messages in file order
//! (bounded memory: one chunk decompressed at a time), [`Recording`] merges several files in
//! log-time order.
//!
//! Every channel's schema must be a conesight message (`conesight.v1.ImageFrame`, ...: the
//! names `conesight_record::message_name` gives), which tells the [`Stream`] of the channel.
//! A file cut short (the recorder was killed: no footer) gives every message before the cut,
//! or before the unfinished chunk it ends with, and reports itself as truncated; damage in a
//! finished file is an error.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use conesight_bus::Stream;
use conesight_proto::Message;
use conesight_record::message_name;
use mcap::records::op;
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

use crate::error::ReplayError;

/// One recorded message.
#[derive(Debug, Clone)]
pub struct RecordedMessage {
    /// Index of its file in the recording (0 for the first file given).
    pub file: usize,
    /// Index of the message in its file.
    pub index: u64,
    /// The channel's topic (the Zenoh key it was recorded on).
    pub topic: Arc<str>,
    /// The stream its schema names.
    pub stream: Stream,
    /// When the recorder received it, ns since the Unix epoch.
    pub log_time_ns: u64,
    /// The protobuf payload as it was on the bus.
    pub data: Vec<u8>,
}

/// The stream whose message `schema` names (`conesight.v1.ImageFrame` -> frames).
pub fn stream_of_schema(schema: &str) -> Option<Stream> {
    Stream::ALL
        .into_iter()
        .find(|stream| message_name(*stream) == schema)
}

fn known_schemas() -> String {
    Stream::ALL
        .iter()
        .map(|s| message_name(*s))
        .collect::<Vec<_>>()
        .join(", ")
}

/// One MCAP file read front to back.
pub struct McapFile {
    path: PathBuf,
    file: File,
    reader: LinearReader,
    state: FileState,
    /// The file's size when opened.
    len: u64,
    at_eof: bool,
    done: bool,
}

#[derive(Default)]
struct FileState {
    /// Schema id -> (name, encoding).
    schemas: HashMap<u16, (String, String)>,
    /// Channel id -> (topic, stream, the ROS 2 type its CDR messages are converted from).
    channels: HashMap<u16, (Arc<str>, Stream, Option<Ros2Channel>)>,
    /// ROS 2 channels of other types than images and camera info (skipped).
    ignored: std::collections::HashSet<u16>,
    /// ROS 2 messages that did not convert (skipped, counted).
    ros2_refused: u64,
    metadata: BTreeMap<String, BTreeMap<String, String>>,
    messages: u64,
    bytes_read: u64,
    saw_data_end: bool,
    truncated: bool,
}

impl McapFile {
    /// Opens `path` and checks that it is an MCAP file.
    pub fn open(path: &Path) -> Result<Self, ReplayError> {
        let io = |source| ReplayError::Io {
            path: path.to_path_buf(),
            source,
        };
        let mut file = File::open(path).map_err(io)?;
        let mut magic = [0_u8; 8];
        let mut filled = 0;
        while filled < magic.len() {
            let n = file.read(&mut magic[filled..]).map_err(io)?;
            if n == 0 {
                break;
            }
            filled += n;
        }
        if magic[..filled] != *mcap::MAGIC {
            return Err(ReplayError::NotMcap {
                path: path.to_path_buf(),
            });
        }
        let len = file.metadata().map_err(io)?.len();
        let reader = LinearReader::new_with_options(
            LinearReaderOptions::default().with_skip_start_magic(true),
        );
        Ok(Self {
            path: path.to_path_buf(),
            file,
            reader,
            state: FileState {
                bytes_read: 8,
                ..FileState::default()
            },
            len,
            at_eof: false,
            done: false,
        })
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Bytes of the file read so far.
    pub fn bytes_read(&self) -> u64 {
        self.state.bytes_read
    }

    /// True once the end was reached and the file was cut short (no summary, or cut inside a
    /// record).
    pub fn truncated(&self) -> bool {
        self.state.truncated
    }

    /// ROS 2 messages of this file skipped because they did not convert (a wrong encoding, a
    /// step that does not match the width, a truncated CDR, an implausible calibration).
    pub fn ros2_refused(&self) -> u64 {
        self.state.ros2_refused
    }

    /// The metadata records read so far (`conesight`, `calibration/<key>`), by name.
    pub fn metadata(&self) -> &BTreeMap<String, BTreeMap<String, String>> {
        &self.state.metadata
    }

    /// True when the file ends with the MCAP magic (a finished file; a killed recorder's file
    /// does not).
    fn has_footer(&self) -> bool {
        use std::io::{Seek, SeekFrom};
        let Ok(mut file) = File::open(&self.path) else {
            return false;
        };
        let mut magic = [0_u8; 8];
        self.len >= 16
            && file.seek(SeekFrom::Start(self.len - 8)).is_ok()
            && file.read_exact(&mut magic).is_ok()
            && magic == *mcap::MAGIC
    }

    /// The next message in file order; `None` at the end (see [`Self::truncated`]).
    pub fn next_message(&mut self, file: usize) -> Result<Option<RecordedMessage>, ReplayError> {
        while !self.done {
            let Some(event) = self.reader.next_event() else {
                self.done = true;
                break;
            };
            let request = match event {
                Ok(LinearReadEvent::ReadRequest(n)) => n,
                Ok(LinearReadEvent::Record { opcode, data }) => {
                    match self.state.record(&self.path, opcode, data, file)? {
                        Some(message) => return Ok(Some(message)),
                        None => continue,
                    }
                }
                Err(source) => {
                    self.done = true;
                    // Cut inside a record: the reader complains at the end of the data (end
                    // of file, or end of a chunk whose rest is missing).
                    if self.at_eof || self.state.bytes_read >= self.len {
                        self.state.truncated = true;
                        tracing::warn!(
                            path = %self.path.display(),
                            messages = self.state.messages,
                            "the recording ends inside a record (the recorder was stopped \
                             abruptly?): every message before the cut was read"
                        );
                        break;
                    }
                    // A file without its footer was cut short: what stops the reader before
                    // the end is the chunk that was open, written in place by a writer that
                    // seeks back to fill in its header (mcap's default, and conesight's
                    // recorder before it appended chunks whole).
                    if !self.has_footer() {
                        self.state.truncated = true;
                        tracing::warn!(
                            path = %self.path.display(),
                            messages = self.state.messages,
                            unread_bytes = self.len - self.state.bytes_read.min(self.len),
                            error = %source,
                            "the recording has no footer and stops at an unfinished record \
                             (the recorder was stopped abruptly while a chunk was open?): every \
                             message before it was read, the bytes after it were not"
                        );
                        break;
                    }
                    return Err(ReplayError::Corrupt {
                        path: self.path.clone(),
                        offset: self.state.bytes_read,
                        source,
                    });
                }
            };
            let buffer = self.reader.insert(request.max(1));
            let n = self.file.read(buffer).map_err(|source| ReplayError::Io {
                path: self.path.clone(),
                source,
            })?;
            self.at_eof |= n == 0;
            self.state.bytes_read += n as u64;
            self.reader.notify_read(n);
        }
        if !self.state.saw_data_end && !self.state.truncated {
            self.state.truncated = true;
            tracing::warn!(
                path = %self.path.display(),
                messages = self.state.messages,
                "the recording has no summary (the recorder was stopped abruptly?): every \
                 message of its closed chunks was read"
            );
        }
        Ok(None)
    }
}

impl FileState {
    fn record(
        &mut self,
        path: &Path,
        opcode: u8,
        data: &[u8],
        file: usize,
    ) -> Result<Option<RecordedMessage>, ReplayError> {
        let parse = |data| {
            mcap::parse_record(opcode, data).map_err(|source| ReplayError::Corrupt {
                path: path.to_path_buf(),
                offset: self.bytes_read,
                source,
            })
        };
        match opcode {
            op::SCHEMA => {
                if let mcap::records::Record::Schema { header, .. } = parse(data)? {
                    self.schemas
                        .insert(header.id, (header.name, header.encoding));
                }
            }
            op::CHANNEL => {
                if let mcap::records::Record::Channel(channel) = parse(data)? {
                    let (schema, encoding) = self
                        .schemas
                        .get(&channel.schema_id)
                        .cloned()
                        .unwrap_or_else(|| ("(none)".to_owned(), String::new()));
                    if encoding == "ros2msg" {
                        match Ros2Channel::of_schema(&schema, &channel.topic) {
                            Some(ros2) => {
                                let stream = ros2.stream();
                                self.channels.insert(
                                    channel.id,
                                    (Arc::from(channel.topic.as_str()), stream, Some(ros2)),
                                );
                            }
                            None => {
                                tracing::info!(
                                    path = %path.display(),
                                    topic = %channel.topic,
                                    schema,
                                    "ROS 2 channel skipped: conesight replays sensor_msgs/msg/Image,                                      CompressedImage and CameraInfo"
                                );
                                self.ignored.insert(channel.id);
                            }
                        }
                        return Ok(None);
                    }
                    let stream = stream_of_schema(&schema)
                        .filter(|_| encoding == conesight_record::SCHEMA_ENCODING);
                    let Some(stream) = stream else {
                        return Err(ReplayError::UnknownSchema {
                            path: path.to_path_buf(),
                            topic: channel.topic,
                            schema,
                            encoding,
                            known: known_schemas(),
                        });
                    };
                    self.channels.insert(
                        channel.id,
                        (Arc::from(channel.topic.as_str()), stream, None),
                    );
                }
            }
            op::MESSAGE => {
                if let mcap::records::Record::Message { header, data } = parse(data)? {
                    if self.ignored.contains(&header.channel_id) {
                        return Ok(None);
                    }
                    let Some((topic, stream, ros2)) = self.channels.get_mut(&header.channel_id)
                    else {
                        return Err(ReplayError::UnknownChannel {
                            path: path.to_path_buf(),
                            channel_id: header.channel_id,
                        });
                    };
                    let index = self.messages;
                    self.messages += 1;
                    let data = match ros2 {
                        None => data.into_owned(),
                        Some(ros2) => match ros2.convert(&data, header.log_time) {
                            Ok(converted) => converted,
                            Err(error) => {
                                self.ros2_refused += 1;
                                if self.ros2_refused.is_power_of_two() {
                                    tracing::warn!(
                                        path = %path.display(),
                                        topic = %topic,
                                        index,
                                        refused = self.ros2_refused,
                                        "ROS 2 message skipped: {error}"
                                    );
                                }
                                return Ok(None);
                            }
                        },
                    };
                    return Ok(Some(RecordedMessage {
                        file,
                        index,
                        topic: topic.clone(),
                        stream: *stream,
                        log_time_ns: header.log_time,
                        data,
                    }));
                }
            }
            op::METADATA => {
                if let mcap::records::Record::Metadata(metadata) = parse(data)? {
                    self.metadata.insert(metadata.name, metadata.metadata);
                }
            }
            op::DATA_END => self.saw_data_end = true,
            _ => {}
        }
        Ok(None)
    }
}

/// A ROS 2 channel replayed: its messages converted to the bus's protobuf (camera id from
/// the topic: its first name, `conesight` skipped, so `/front/image_raw` and
/// `/front/camera_info` are camera `front`; sequence numbers counted per channel; acquisition
/// time from the message's header stamp).
#[derive(Debug)]
struct Ros2Channel {
    kind: Ros2Kind,
    camera: String,
    next_sequence: u64,
}

#[derive(Debug, Clone, Copy)]
enum Ros2Kind {
    Image,
    CompressedImage,
    CameraInfo,
}

impl Ros2Channel {
    fn of_schema(schema: &str, topic: &str) -> Option<Self> {
        let kind = match schema {
            "sensor_msgs/msg/Image" => Ros2Kind::Image,
            "sensor_msgs/msg/CompressedImage" => Ros2Kind::CompressedImage,
            "sensor_msgs/msg/CameraInfo" => Ros2Kind::CameraInfo,
            _ => return None,
        };
        let camera = topic
            .split('/')
            .filter(|part| !part.is_empty() && *part != "conesight")
            .find(|part| !matches!(*part, "image_raw" | "image" | "camera_info" | "compressed"))
            .map_or_else(
                || "camera".to_owned(),
                |part| {
                    part.chars()
                        .map(|c| {
                            if c.is_ascii_alphanumeric() {
                                c.to_ascii_lowercase()
                            } else {
                                '_'
                            }
                        })
                        .collect()
                },
            );
        Some(Self {
            kind,
            camera,
            next_sequence: 0,
        })
    }

    fn stream(&self) -> Stream {
        match self.kind {
            Ros2Kind::CameraInfo => Stream::CameraInfo,
            Ros2Kind::Image | Ros2Kind::CompressedImage => Stream::Frame,
        }
    }

    /// The CDR `data` as the bus's protobuf message.
    fn convert(&mut self, data: &[u8], log_time_ns: u64) -> Result<Vec<u8>, String> {
        use conesight_proto::pb;
        use conesight_ros2::msg;
        let header = |ros: &msg::Header, sequence: u64| {
            let stamp = ros
                .stamp
                .to_ns()
                .filter(|ns| *ns > 0)
                .unwrap_or(log_time_ns);
            let frame_id = if ros.frame_id.is_empty() {
                format!("{}_optical", self.camera)
            } else {
                ros.frame_id.clone()
            };
            pb::Header::new(&self.camera, sequence, stamp, &frame_id)
        };
        let sequence = self.next_sequence;
        let encoded = match self.kind {
            Ros2Kind::Image => {
                let image: msg::Image =
                    conesight_ros2::from_cdr(data).map_err(|e| e.to_string())?;
                let rgb =
                    conesight_ros2::convert::rgb_from_image(&image).map_err(|e| e.to_string())?;
                pb::ImageFrame::from_rgb(header(&image.header, sequence), &rgb).encode_to_vec()
            }
            Ros2Kind::CompressedImage => {
                let image: msg::CompressedImage =
                    conesight_ros2::from_cdr(data).map_err(|e| e.to_string())?;
                let format = image.format.to_ascii_lowercase();
                if !format.contains("jpeg") && !format.contains("jpg") {
                    return Err(format!(
                        "sensor_msgs/msg/CompressedImage format {:?}: conesight replays JPEG",
                        image.format
                    ));
                }
                let (width_px, height_px) = conesight_vision::decode::jpeg_size(&image.data)
                    .map_err(|e| format!("sensor_msgs/msg/CompressedImage: {e}"))?;
                pb::ImageFrame {
                    header: Some(header(&image.header, sequence)),
                    width_px,
                    height_px,
                    encoding: pb::ImageEncoding::Jpeg.into(),
                    data: image.data.into(),
                }
                .encode_to_vec()
            }
            Ros2Kind::CameraInfo => {
                let info: msg::CameraInfo =
                    conesight_ros2::from_cdr(data).map_err(|e| e.to_string())?;
                let camera =
                    conesight_ros2::convert::camera_from_ros(&info).map_err(|e| e.to_string())?;
                pb::CameraInfo::new(header(&info.header, sequence), &camera, None).encode_to_vec()
            }
        };
        self.next_sequence += 1;
        Ok(encoded)
    }
}

/// Several files read as one recording, messages merged in log-time order (ties: the file
/// given first). One message per file is held at a time.
pub struct Recording {
    files: Vec<McapFile>,
    heads: Vec<Option<RecordedMessage>>,
    total_bytes: u64,
}

impl Recording {
    /// Opens every file (checking each is MCAP) and reads the first message of each.
    pub fn open(paths: &[PathBuf]) -> Result<Self, ReplayError> {
        if paths.is_empty() {
            return Err(ReplayError::Options("no recording given".to_owned()));
        }
        let mut files = Vec::new();
        let mut total_bytes = 0;
        for path in paths {
            let file = McapFile::open(path)?;
            total_bytes += std::fs::metadata(path)
                .map_err(|source| ReplayError::Io {
                    path: path.clone(),
                    source,
                })?
                .len();
            files.push(file);
        }
        let mut heads = Vec::new();
        for (index, file) in files.iter_mut().enumerate() {
            heads.push(file.next_message(index)?);
        }
        Ok(Self {
            files,
            heads,
            total_bytes,
        })
    }

    /// The next message in log-time order; `None` when every file is read.
    pub fn next_message(&mut self) -> Result<Option<RecordedMessage>, ReplayError> {
        let next = self
            .heads
            .iter()
            .enumerate()
            .filter_map(|(i, head)| head.as_ref().map(|m| (m.log_time_ns, i)))
            .min();
        let Some((_, index)) = next else {
            return Ok(None);
        };
        let refill = self.files[index].next_message(index)?;
        Ok(std::mem::replace(&mut self.heads[index], refill))
    }

    /// Sum of the files' sizes, bytes.
    pub fn total_bytes(&self) -> u64 {
        self.total_bytes
    }

    /// Bytes read so far over every file.
    pub fn bytes_read(&self) -> u64 {
        self.files.iter().map(McapFile::bytes_read).sum()
    }

    /// The files that ended short (so far).
    pub fn truncated(&self) -> Vec<PathBuf> {
        self.files
            .iter()
            .filter(|f| f.truncated())
            .map(|f| f.path().to_path_buf())
            .collect()
    }

    /// ROS 2 messages skipped because they did not convert, in every file so far.
    pub fn ros2_refused(&self) -> u64 {
        self.files.iter().map(McapFile::ros2_refused).sum()
    }

    /// The path of file `index`.
    pub fn path(&self, index: usize) -> &Path {
        self.files
            .get(index)
            .map_or_else(|| Path::new("?"), |f| f.path())
    }

    /// The metadata of file `index` read so far.
    pub fn metadata(&self, index: usize) -> Option<&BTreeMap<String, BTreeMap<String, String>>> {
        self.files.get(index).map(McapFile::metadata)
    }
}

/// `message` decoded as `M` (its stream's type), or an error naming the file and channel.
pub fn decode_message<M: Message + Default>(
    path: &Path,
    message: &RecordedMessage,
) -> Result<M, ReplayError> {
    M::decode(&message.data[..]).map_err(|error| ReplayError::Undecodable {
        path: path.to_path_buf(),
        topic: message.topic.to_string(),
        schema: message_name(message.stream),
        index: message.index,
        log_time_ns: message.log_time_ns,
        reason: error.to_string(),
    })
}
