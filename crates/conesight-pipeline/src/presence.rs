//! What a service tells the bus about itself, so dashboards find and query it:
//!
//! - a liveliness token `conesight/<ns>/<vehicle>/@service/<service>/<zid>` for as long as it
//!   runs (gone within a transport's close when the process dies);
//! - queryables under that key: `/health` (JSON: readiness and counters), `/manifest` (JSON:
//!   version, git revision, model sha256s, streams in and out) and `/schema` (the protobuf
//!   `FileDescriptorSet` of every bus message);
//! - [`Output`]: a publisher that keeps its latest message and answers a `get` on the stream's
//!   own key with it, so a late joiner has the latest cones within one query round trip.
//!
//! Keys are built by [`conesight_bus::Topics`]; `@service` is a verbatim chunk, so no `*` or
//! `**` of a stream subscriber or recorder ever matches it.

use std::sync::{Arc, Mutex, PoisonError};

use conesight_bus::zenoh::Wait;
use conesight_bus::zenoh::bytes::{Encoding, ZBytes};
use conesight_bus::zenoh::key_expr::KeyExpr;
use conesight_bus::zenoh::liveliness::LivelinessToken;
use conesight_bus::zenoh::pubsub::Publisher;
use conesight_bus::zenoh::query::{Query, Queryable};
use conesight_bus::{BusError, ServiceQuery, Stream, declare_publisher};
use serde::{Deserialize, Serialize};

use crate::node::Node;

/// Version of the conesight build (the workspace version).
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
/// Git revision the binary was built from (`unknown` outside a checkout).
pub const GIT_REVISION: &str = env!("CONESIGHT_GIT_REVISION");
/// Encoding of `/schema` replies.
pub const SCHEMA_ENCODING: &str = "application/protobuf;google.protobuf.FileDescriptorSet";

/// A model a service runs, as the manifest and `conesight_build_info` name it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ModelIdentity {
    /// File name (`detector.onnx`).
    pub file: String,
    /// The path it was loaded from.
    pub path: String,
    /// sha256 of the file, lowercase hex (as `sha256sum` prints it).
    pub sha256: String,
}

impl ModelIdentity {
    /// The identity of the model file at `path` (reads it to hash it).
    pub fn of_file(path: &std::path::Path) -> std::io::Result<Self> {
        Ok(Self {
            file: path
                .file_name()
                .map_or_else(String::new, |name| name.to_string_lossy().into_owned()),
            path: path.display().to_string(),
            sha256: sha256_hex(path)?,
        })
    }
}

/// The sha256 of a file, lowercase hex, read in blocks.
pub fn sha256_hex(path: &std::path::Path) -> std::io::Result<String> {
    use sha2::Digest;
    let mut file = std::fs::File::open(path)?;
    let mut hasher = sha2::Sha256::new();
    std::io::copy(&mut file, &mut hasher)?;
    Ok(hasher
        .finalize()
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect())
}

/// What `/manifest` answers.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Manifest {
    /// Service name (`detector`, ...).
    pub service: String,
    /// The Zenoh session id of its process (shared by the services of one `conesight run`).
    pub zid: String,
    /// Run namespace and vehicle.
    pub namespace: String,
    /// Vehicle key chunk.
    pub vehicle: String,
    /// See [`VERSION`].
    pub version: String,
    /// See [`GIT_REVISION`].
    pub git_revision: String,
    /// Models loaded (none for camera and localiser).
    pub models: Vec<ModelIdentity>,
    /// Keys subscribed to.
    pub inputs: Vec<String>,
    /// Keys published to (each also answers a `get` with its latest message).
    pub outputs: Vec<String>,
    /// The keys of `/health`, `/manifest`, `/schema`.
    pub queries: Vec<String>,
}

/// What `/health` answers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Health {
    /// Service name.
    pub service: String,
    /// Session id of its process.
    pub zid: String,
    /// `/readyz` would answer 200.
    pub ready: bool,
    /// Model loaded.
    pub model_loaded: bool,
    /// Zenoh session open.
    pub session_up: bool,
    /// The frame source delivers (camera).
    pub source_up: bool,
    /// Latest input recent enough.
    pub inputs_fresh: bool,
    /// Seconds since the latest input, `null` before the first.
    pub input_age_secs: Option<f64>,
    /// Inputs received, processed, dropped so far.
    pub frames_received: u64,
    /// See `frames_received`.
    pub frames_processed: u64,
    /// See `frames_received`.
    pub frames_dropped: u64,
    /// What the service says of itself (`/readyz` detail lines, e.g. the detector's coverage).
    pub details: std::collections::BTreeMap<String, String>,
}

impl Node {
    /// The state `/health` answers now.
    pub fn health(&self) -> Health {
        let report = self.readiness.report();
        Health {
            service: self.name.to_owned(),
            zid: self.session.zid().to_string(),
            ready: report.is_ready(),
            model_loaded: report.model_loaded,
            session_up: report.session_up,
            source_up: report.source_up,
            inputs_fresh: report.inputs_fresh,
            input_age_secs: report.input_age_secs,
            frames_received: self.metrics.frames_received_count(),
            frames_processed: self.metrics.frames_processed_count(),
            frames_dropped: self.metrics.frames_dropped_count(),
            details: report.details.into_iter().collect(),
        }
    }

    /// The manifest as it stands (models and streams are added as the service starts).
    pub fn manifest(&self) -> Manifest {
        let state = self.identity.lock().unwrap_or_else(PoisonError::into_inner);
        let zid = self.session.zid().to_string();
        Manifest {
            service: self.name.to_owned(),
            namespace: self.topics.namespace().to_owned(),
            vehicle: self.topics.vehicle().to_owned(),
            version: VERSION.to_owned(),
            git_revision: GIT_REVISION.to_owned(),
            models: state.models.clone(),
            inputs: state.inputs.clone(),
            outputs: state.outputs.clone(),
            queries: [
                ServiceQuery::Health,
                ServiceQuery::Manifest,
                ServiceQuery::Schema,
            ]
            .iter()
            .filter_map(|query| self.topics.service_query(self.name, &zid, *query).ok())
            .map(|key| key.to_string())
            .collect(),
            zid,
        }
    }

    /// Records that the service subscribes to `key`.
    pub fn add_input(&self, key: &KeyExpr<'_>) {
        push_unique(
            &mut self
                .identity
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .inputs,
            key.to_string(),
        );
    }

    /// Records the model the service loaded (manifest and `conesight_build_info`); a model
    /// that cannot be read for its hash is named with an empty sha256 and a warning.
    pub fn add_model(&self, path: &std::path::Path) {
        let identity = ModelIdentity::of_file(path).unwrap_or_else(|error| {
            tracing::warn!(service = self.name, model = %path.display(), %error, "cannot hash the model for the manifest");
            ModelIdentity {
                file: path
                    .file_name()
                    .map_or_else(String::new, |name| name.to_string_lossy().into_owned()),
                path: path.display().to_string(),
                sha256: String::new(),
            }
        });
        self.metrics.set_build_info(&conesight_service::BuildInfo {
            version: VERSION.to_owned(),
            git_revision: GIT_REVISION.to_owned(),
            model: identity.file.clone(),
            model_sha256: identity.sha256.clone(),
        });
        let mut state = self.identity.lock().unwrap_or_else(PoisonError::into_inner);
        state.models.retain(|model| model.path != identity.path);
        state.models.push(identity);
    }

    /// A publisher on `camera`'s `stream` that keeps its latest message and answers a `get`
    /// on the stream's key with it; recorded in the manifest.
    pub async fn declare_output(&self, camera: &str, stream: Stream) -> Result<Output, BusError> {
        let publisher = declare_publisher(&self.session, &self.topics, camera, stream).await?;
        let key = publisher.key_expr().clone().into_owned();
        let latest: Arc<Mutex<Option<ZBytes>>> = Arc::default();
        let cache = latest.clone();
        let reply_key = key.clone();
        let queryable = self
            .queryable(key.clone(), move |query: Query| {
                let payload = cache.lock().unwrap_or_else(PoisonError::into_inner).clone();
                if let Some(payload) = payload {
                    reply(&query, &reply_key, payload, Encoding::APPLICATION_PROTOBUF);
                }
            })
            .await?;
        push_unique(
            &mut self
                .identity
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .outputs,
            key.to_string(),
        );
        Ok(Output {
            publisher,
            latest,
            _queryable: queryable,
        })
    }

    /// Declares the service's liveliness token and its `/health`, `/manifest` and `/schema`
    /// queryables; they live as long as the returned [`Presence`].
    pub async fn announce(&self) -> Result<Presence, BusError> {
        let zid = self.session.zid().to_string();
        let token_key = self.topics.service_token(self.name, &zid)?;
        let token = self
            .session
            .liveliness()
            .declare_token(token_key.clone())
            .await
            .map_err(|source| BusError::Declare {
                role: "liveliness token",
                key: token_key.to_string(),
                source,
            })?;
        let mut queryables = Vec::new();
        for query in [
            ServiceQuery::Health,
            ServiceQuery::Manifest,
            ServiceQuery::Schema,
        ] {
            let key = self.topics.service_query(self.name, &zid, query)?;
            let node = self.clone();
            let reply_key = key.clone();
            let queryable = self
                .queryable(key.clone(), move |request: Query| match query {
                    ServiceQuery::Health => {
                        let json = serde_json::to_vec(&node.health()).unwrap_or_default();
                        reply(
                            &request,
                            &reply_key,
                            json.into(),
                            Encoding::APPLICATION_JSON,
                        );
                    }
                    ServiceQuery::Manifest => {
                        let json = serde_json::to_vec(&node.manifest()).unwrap_or_default();
                        reply(
                            &request,
                            &reply_key,
                            json.into(),
                            Encoding::APPLICATION_JSON,
                        );
                    }
                    ServiceQuery::Schema => reply(
                        &request,
                        &reply_key,
                        ZBytes::from(conesight_proto::FILE_DESCRIPTOR_SET),
                        Encoding::from(SCHEMA_ENCODING),
                    ),
                })
                .await?;
            queryables.push(queryable);
        }
        tracing::debug!(service = self.name, key = %token_key, "announced on the bus");
        Ok(Presence {
            _token: token,
            _queryables: queryables,
        })
    }
}

impl Node {
    /// A queryable on `key` answered by `callback` on Zenoh's thread.
    async fn queryable(
        &self,
        key: KeyExpr<'static>,
        callback: impl Fn(Query) + Send + Sync + 'static,
    ) -> Result<Queryable<()>, BusError> {
        self.session
            .declare_queryable(key.clone())
            .callback(callback)
            .await
            .map_err(|source| BusError::Declare {
                role: "queryable",
                key: key.to_string(),
                source,
            })
    }
}

fn push_unique(list: &mut Vec<String>, key: String) {
    if !list.contains(&key) {
        list.push(key);
    }
}

/// Replies to `query` from Zenoh's callback thread; a failed reply (the querier left) is
/// logged at debug level only.
fn reply(query: &Query, key: &KeyExpr<'static>, payload: ZBytes, encoding: Encoding) {
    if let Err(error) = query.reply(key.clone(), payload).encoding(encoding).wait() {
        tracing::debug!(%key, %error, "query reply failed");
    }
}

/// The models, inputs and outputs a [`Node`] has declared (behind its manifest).
#[derive(Debug, Default)]
pub struct Identity {
    models: Vec<ModelIdentity>,
    inputs: Vec<String>,
    outputs: Vec<String>,
}

/// A service's liveliness token and service queryables; dropping it withdraws them.
#[derive(Debug)]
pub struct Presence {
    _token: LivelinessToken,
    _queryables: Vec<Queryable<()>>,
}

/// A publisher that keeps its latest message for `get`s on its key ([`Node::declare_output`]).
#[derive(Debug)]
pub struct Output {
    publisher: Publisher<'static>,
    latest: Arc<Mutex<Option<ZBytes>>>,
    _queryable: Queryable<()>,
}

impl Output {
    /// Publishes `payload` (blocking only as far as Zenoh's Drop congestion control lets it)
    /// and keeps it as the latest; for worker threads.
    pub fn put(&self, payload: ZBytes) -> Result<(), BusError> {
        self.keep(&payload);
        self.publisher
            .put(payload)
            .wait()
            .map_err(|source| self.put_error(source))
    }

    /// [`Output::put`] from async code.
    pub async fn publish(&self, payload: ZBytes) -> Result<(), BusError> {
        self.keep(&payload);
        self.publisher
            .put(payload)
            .await
            .map_err(|source| self.put_error(source))
    }

    /// The key it publishes on.
    pub fn key_expr(&self) -> &KeyExpr<'static> {
        self.publisher.key_expr()
    }

    fn keep(&self, payload: &ZBytes) {
        *self.latest.lock().unwrap_or_else(PoisonError::into_inner) = Some(payload.clone());
    }

    fn put_error(&self, source: conesight_bus::zenoh::Error) -> BusError {
        BusError::Put {
            key: self.publisher.key_expr().to_string(),
            source,
        }
    }
}
