//! [`McapSink`]: messages into MCAP files with zstd chunks, rolled by size or time.
//!
//! The writer goes straight to the file (no user-space buffer): a chunk is compressed in
//! memory while it fills (at most `chunk_bytes` plus one message) and appended to the file
//! whole when it closes, so after a `kill -9` every closed chunk is on disk and readable; only
//! the open chunk and the summary are lost. Chunks also close every `flush_interval`, so at a
//! low message rate little is lost either. (`mcap`'s default writes a chunk in place instead: a
//! placeholder header, the compressed data as zstd emits it, then a seek back to fill in the
//! header. A kill in between leaves a header no reader can get past, so seeking is off.)

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use conesight_bus::Stream;

use crate::error::RecordError;
use crate::schema::{MESSAGE_ENCODING, SCHEMA_ENCODING, message_name};

/// Options of a [`McapSink`].
#[derive(Debug, Clone)]
pub struct SinkOptions {
    /// Target uncompressed chunk size, bytes.
    pub chunk_bytes: u64,
    /// zstd level (1 is fast enough for raw frames at 20 Hz on one core).
    pub zstd_level: u32,
    /// Start a new file once the current one passes this many bytes (`None`: never).
    pub split_bytes: Option<u64>,
    /// Start a new file after this long (`None`: never).
    pub split_after: Option<Duration>,
    /// Close the open chunk at least this often.
    pub flush_interval: Duration,
    /// Key-value metadata written at the start of every file (record name `conesight`).
    pub metadata: BTreeMap<String, String>,
}

impl Default for SinkOptions {
    fn default() -> Self {
        Self {
            chunk_bytes: 8 << 20,
            zstd_level: 1,
            split_bytes: None,
            split_after: None,
            flush_interval: Duration::from_secs(1),
            metadata: BTreeMap::new(),
        }
    }
}

/// The path of file `index` of a recording named `base`: `base` itself without splitting,
/// else `drive_0003.mcap` for `drive.mcap`.
pub fn split_path(base: &Path, index: u32, splitting: bool) -> PathBuf {
    if !splitting {
        return base.to_path_buf();
    }
    let stem = base
        .file_stem()
        .map_or_else(|| "recording".into(), |s| s.to_string_lossy().into_owned());
    let ext = base
        .extension()
        .map_or_else(|| "mcap".into(), |s| s.to_string_lossy().into_owned());
    base.with_file_name(format!("{stem}_{index:04}.{ext}"))
}

struct OpenFile {
    path: PathBuf,
    writer: mcap::Writer<File>,
    size_probe: File,
    channels: HashMap<String, u16>,
    sequence: u32,
    opened: Instant,
    last_flush: Instant,
}

/// MCAP files being written (see the module docs).
pub struct McapSink {
    base: PathBuf,
    options: SinkOptions,
    index: u32,
    file: Option<OpenFile>,
    written: Vec<PathBuf>,
    /// Extra metadata records seen so far (calibration per camera), repeated in every file.
    records: BTreeMap<String, BTreeMap<String, String>>,
}

impl McapSink {
    /// Creates the first file of the recording `base`.
    pub fn create(base: &Path, options: SinkOptions) -> Result<Self, RecordError> {
        let mut sink = Self {
            base: base.to_path_buf(),
            options,
            index: 0,
            file: None,
            written: Vec::new(),
            records: BTreeMap::new(),
        };
        sink.open_next()?;
        Ok(sink)
    }

    fn splitting(&self) -> bool {
        self.options.split_bytes.is_some() || self.options.split_after.is_some()
    }

    fn open_next(&mut self) -> Result<(), RecordError> {
        let path = split_path(&self.base, self.index, self.splitting());
        self.index += 1;
        let io = |source| RecordError::Io {
            path: path.clone(),
            source,
        };
        if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent).map_err(io)?;
        }
        let file = File::create(&path).map_err(io)?;
        let size_probe = file.try_clone().map_err(io)?;
        let writer = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .compression_level(self.options.zstd_level)
            .chunk_size(Some(self.options.chunk_bytes))
            // Chunks buffered in memory and appended whole (see the module docs).
            .disable_seeking(true)
            .profile("")
            .library(concat!("conesight-record ", env!("CARGO_PKG_VERSION")))
            .create(file)
            .map_err(|source| RecordError::Mcap {
                path: path.clone(),
                source,
            })?;
        let now = Instant::now();
        let mut open = OpenFile {
            path,
            writer,
            size_probe,
            channels: HashMap::new(),
            sequence: 0,
            opened: now,
            last_flush: now,
        };
        write_metadata(&mut open, "conesight", &self.options.metadata)?;
        for (name, record) in &self.records {
            write_metadata(&mut open, name, record)?;
        }
        tracing::info!(path = %open.path.display(), "recording");
        self.file = Some(open);
        Ok(())
    }

    /// Adds a metadata record to the current file and to every later one.
    pub fn add_metadata(
        &mut self,
        name: &str,
        record: BTreeMap<String, String>,
    ) -> Result<(), RecordError> {
        if let Some(open) = self.file.as_mut() {
            write_metadata(open, name, &record)?;
        }
        self.records.insert(name.to_owned(), record);
        Ok(())
    }

    /// Writes one message of `stream` on channel `topic` (the Zenoh key).
    pub fn write(
        &mut self,
        topic: &str,
        stream: Stream,
        log_time_ns: u64,
        publish_time_ns: u64,
        data: &[u8],
    ) -> Result<(), RecordError> {
        self.roll_if_due()?;
        let Some(open) = self.file.as_mut() else {
            return Err(RecordError::Thread("has no open file"));
        };
        let path = open.path.clone();
        let mcap_error = |source| RecordError::Mcap {
            path: path.clone(),
            source,
        };
        let channel_id = match open.channels.get(topic) {
            Some(id) => *id,
            None => {
                let schema = open
                    .writer
                    .add_schema(
                        message_name(stream),
                        SCHEMA_ENCODING,
                        conesight_proto::FILE_DESCRIPTOR_SET,
                    )
                    .map_err(mcap_error)?;
                let id = open
                    .writer
                    .add_channel(schema, topic, MESSAGE_ENCODING, &BTreeMap::new())
                    .map_err(mcap_error)?;
                open.channels.insert(topic.to_owned(), id);
                id
            }
        };
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: open.sequence,
            log_time: log_time_ns,
            publish_time: publish_time_ns,
        };
        open.sequence = open.sequence.wrapping_add(1);
        open.writer
            .write_to_known_channel(&header, data)
            .map_err(mcap_error)?;
        if open.last_flush.elapsed() >= self.options.flush_interval {
            open.writer.flush().map_err(mcap_error)?;
            open.last_flush = Instant::now();
        }
        Ok(())
    }

    fn roll_if_due(&mut self) -> Result<(), RecordError> {
        let Some(open) = self.file.as_ref() else {
            return Ok(());
        };
        let by_time = self
            .options
            .split_after
            .is_some_and(|after| open.opened.elapsed() >= after);
        let by_size = self.options.split_bytes.is_some_and(|limit| {
            open.size_probe
                .metadata()
                .is_ok_and(|meta| meta.len() >= limit)
        });
        if by_time || by_size {
            self.close_current()?;
            self.open_next()?;
        }
        Ok(())
    }

    fn close_current(&mut self) -> Result<(), RecordError> {
        if let Some(mut open) = self.file.take() {
            open.writer.finish().map_err(|source| RecordError::Mcap {
                path: open.path.clone(),
                source,
            })?;
            self.written.push(open.path);
        }
        Ok(())
    }

    /// Finishes the open file (chunk, indexes, summary) and returns every file written.
    pub fn finish(mut self) -> Result<Vec<PathBuf>, RecordError> {
        self.close_current()?;
        Ok(std::mem::take(&mut self.written))
    }
}

fn write_metadata(
    open: &mut OpenFile,
    name: &str,
    record: &BTreeMap<String, String>,
) -> Result<(), RecordError> {
    open.writer
        .write_metadata(&mcap::records::Metadata {
            name: name.to_owned(),
            metadata: record.clone(),
        })
        .map_err(|source| RecordError::Mcap {
            path: open.path.clone(),
            source,
        })
}
