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
    /// Channel id -> (topic, stream).
    channels: HashMap<u16, (Arc<str>, Stream)>,
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
                    self.channels
                        .insert(channel.id, (Arc::from(channel.topic.as_str()), stream));
                }
            }
            op::MESSAGE => {
                if let mcap::records::Record::Message { header, data } = parse(data)? {
                    let Some((topic, stream)) = self.channels.get(&header.channel_id) else {
                        return Err(ReplayError::UnknownChannel {
                            path: path.to_path_buf(),
                            channel_id: header.channel_id,
                        });
                    };
                    let index = self.messages;
                    self.messages += 1;
                    return Ok(Some(RecordedMessage {
                        file,
                        index,
                        topic: topic.clone(),
                        stream: *stream,
                        log_time_ns: header.log_time,
                        data: data.into_owned(),
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
