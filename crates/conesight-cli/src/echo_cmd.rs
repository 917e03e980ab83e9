//! `conesight echo STREAM`: a stream's messages as JSON lines, decoded through the protobuf
//! descriptors every service serves (`conesight_proto::FILE_DESCRIPTOR_SET`), so any tool that
//! reads JSON (jq, Python, a dashboard) reads the bus with no generated code.
//!
//! Each line is `{"key": ..., "message": {...}}`: field names as in `proto/conesight/v1`
//! (`class`, not `class_`), enums by name, every field present (zero values too), 64-bit
//! integers (stamps in ns) as JSON numbers. A frame's pixels are left out (`data_bytes` says how
//! many there were) unless `--with-pixels` (base64). By default the latest message of every
//! matching key is asked for first (a `get` answered by the service that publishes it), so a
//! late joiner prints something at once.

use std::collections::HashMap;
use std::time::Duration;

use anyhow::Context;
use conesight_bus::zenoh::sample::Sample;
use conesight_bus::{Stream, Topics, ZenohArgs, declare_subscriber, open_session};
use conesight_pipeline::Shutdown;
use prost_reflect::{DescriptorPool, DynamicMessage, MessageDescriptor, SerializeOptions};

use crate::record_cmd::StreamName;

/// Arguments of `conesight echo`.
#[derive(Debug, clap::Args)]
pub struct EchoArgs {
    /// The stream to print.
    #[arg(value_enum)]
    stream: StreamName,
    /// Zenoh session and keys: `--namespace` and `--vehicle` name the run.
    #[command(flatten)]
    zenoh: ZenohArgs,
    /// Only this camera's messages (default: every camera).
    #[arg(long)]
    camera: Option<String>,
    /// Stop after this many messages.
    #[arg(long, short = 'n')]
    count: Option<u64>,
    /// Do not ask for the latest message first; print only messages published from now on.
    #[arg(long = "no-latest")]
    no_latest: bool,
    /// Print a frame's pixels (base64) instead of their size.
    #[arg(long = "with-pixels")]
    with_pixels: bool,
    /// Largest message decoded, MiB.
    #[arg(long = "max-message-mb", default_value_t = 64)]
    max_message_mb: usize,
}

/// Turns bus payloads of one stream into JSON lines.
pub struct JsonLines {
    descriptor: MessageDescriptor,
    with_pixels: bool,
    limit: usize,
    options: SerializeOptions,
}

impl JsonLines {
    /// A printer of `stream`'s messages.
    pub fn new(stream: Stream, with_pixels: bool, limit: usize) -> anyhow::Result<Self> {
        let pool = DescriptorPool::decode(conesight_proto::FILE_DESCRIPTOR_SET)
            .context("the built-in protobuf descriptors do not decode (a build problem)")?;
        let name = conesight_record::message_name(stream);
        let descriptor = pool
            .get_message_by_name(name)
            .with_context(|| format!("no message {name} in the built-in descriptors"))?;
        Ok(Self {
            descriptor,
            with_pixels,
            limit,
            options: SerializeOptions::new()
                .use_proto_field_name(true)
                .skip_default_fields(false)
                .stringify_64_bit_integers(false),
        })
    }

    /// One JSON line for a message on `key`; an error names the key and what is wrong.
    pub fn line(&self, key: &str, payload: &[u8]) -> anyhow::Result<String> {
        if payload.len() > self.limit {
            anyhow::bail!(
                "{key}: message of {} bytes is over --max-message-mb ({} bytes)",
                payload.len(),
                self.limit
            );
        }
        let mut message = DynamicMessage::decode(self.descriptor.clone(), payload)
            .with_context(|| format!("{key}: not a {}", self.descriptor.full_name()))?;
        let mut data_bytes = None;
        if !self.with_pixels
            && let Some(field) = self.descriptor.get_field_by_name("data")
        {
            data_bytes = message
                .get_field(&field)
                .as_bytes()
                .map(|bytes| bytes.len());
            message.clear_field(&field);
        }
        let mut body = Vec::new();
        message
            .serialize_with_options(&mut serde_json::Serializer::new(&mut body), &self.options)?;
        let body: serde_json::Value = serde_json::from_slice(&body)?;
        let mut line = serde_json::json!({ "key": key, "message": body });
        if let Some(bytes) = data_bytes {
            line["message"]["data"] = serde_json::Value::Null;
            line["data_bytes"] = bytes.into();
        }
        Ok(line.to_string())
    }
}

/// Runs `conesight echo`.
pub fn run(args: &EchoArgs) -> anyhow::Result<()> {
    conesight_service::init_tracing();
    let runtime = crate::async_runtime()?;
    runtime.block_on(run_async(args))
}

async fn run_async(args: &EchoArgs) -> anyhow::Result<()> {
    let shutdown = Shutdown::new();
    shutdown.trigger_on_signal();
    let stream = Stream::from(args.stream);
    let printer = JsonLines::new(
        stream,
        args.with_pixels,
        args.max_message_mb.saturating_mul(1 << 20),
    )?;
    let session = open_session(&args.zenoh).await?;
    let topics = Topics::from_args(&args.zenoh)?;
    let key = match &args.camera {
        Some(camera) => topics.key(camera, stream)?,
        None => topics.all_cameras(stream)?,
    };
    // Subscribe first, then ask for the latest: nothing published in between is missed.
    let subscriber = declare_subscriber(&session, key.clone(), stream).await?;
    let mut printed = 0u64;
    // The (camera) key's last printed header, so a message both answered and received is
    // printed once.
    let mut last: HashMap<String, (u64, u64)> = HashMap::new();
    let mut print = |sample: &Sample| -> bool {
        let key = sample.key_expr().as_str();
        let payload = sample.payload().to_bytes();
        let header = conesight_proto::peek_header(&payload[..])
            .ok()
            .map(|h| (h.frame_sequence, h.publish_time_ns));
        if header.is_some() && last.get(key) == header.as_ref() {
            return false;
        }
        match printer.line(key, &payload) {
            Ok(line) => {
                println!("{line}");
                if let Some(header) = header {
                    last.insert(key.to_owned(), header);
                }
                printed += 1;
            }
            Err(error) => eprintln!("conesight echo: {error:#}"),
        }
        args.count.is_some_and(|count| printed >= count)
    };
    if !args.no_latest {
        let replies = session
            .get(key.clone())
            .timeout(Duration::from_secs(1))
            .await
            .map_err(|error| anyhow::anyhow!("query for the latest {key} failed: {error}"))?;
        while let Ok(reply) = replies.recv_async().await {
            if let Ok(sample) = reply.result()
                && print(sample)
            {
                return Ok(());
            }
        }
    }
    loop {
        tokio::select! {
            () = shutdown.wait() => return Ok(()),
            sample = subscriber.recv_async() => {
                let Ok(sample) = sample else { return Ok(()) };
                if print(&sample) {
                    return Ok(());
                }
            }
        }
    }
}
