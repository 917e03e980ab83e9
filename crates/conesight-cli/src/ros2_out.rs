//! `conesight run --ros2 dds|zenoh` and `conesight ros2`: the run's cones and calibration as
//! ROS 2 topics: `/conesight/<camera>/cones` (`conesight_msgs/msg/ConeArray`, each cone with its
//! keypoints from the same frame's keypoints message), `/conesight/<camera>/cone_markers`
//! (`visualization_msgs/msg/MarkerArray`, for RViz) and `/conesight/<camera>/camera_info`
//! (`sensor_msgs/msg/CameraInfo`), on `ROS_DOMAIN_ID` (0 when unset), either
//! - over DDS (`conesight_ros2::dds`: `rt/` topics, `dds_::` types, CDR, ROS 2's default QoS),
//!   as a ROS 2 node on Cyclone DDS or Fast DDS reads them; or
//! - in rmw_zenoh's format on the run's own Zenoh session (`conesight_ros2::rmw_zenoh`), published
//!   by node `conesight`.
//!
//! A message that does not convert or publish is logged (rate-limited), counted
//! (`conesight_errors_total{kind="ros2_output"}`) and not published.

use std::any::Any;
use std::collections::{BTreeMap, VecDeque};

use anyhow::Context;
use conesight_bus::zenoh::Session;
use conesight_bus::zenoh::liveliness::LivelinessToken;
use conesight_bus::{Stream, Topics, declare_subscriber, decode};
use conesight_pipeline::{Node, Shutdown};
use conesight_proto::{ConeKeypoints, now_ns, pb};
use conesight_ros2::dds::{self, Dds, DdsMessage};
use conesight_ros2::msg::RosMessage;
use conesight_ros2::rmw_zenoh;

/// The ROS 2 node's name.
const NODE: &str = "conesight";
/// Keypoints messages kept per camera to give each cone its keypoints.
const KEYPOINTS_KEPT: usize = 32;

/// Which ROS 2 middleware the topics go out on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Rmw {
    /// DDS (RTPS over UDP): what ROS 2 nodes on rmw_cyclonedds_cpp or rmw_fastrtps_cpp read.
    Dds,
    /// rmw_zenoh's key expressions, attachments and liveliness tokens on this run's session.
    Zenoh,
}

/// One rmw_zenoh publisher: its key, GID, sequence and liveliness token.
struct ZenohPublisher {
    key: String,
    gid: [u8; 16],
    sequence: i64,
    _token: LivelinessToken,
}

/// rmw_zenoh on the run's session.
struct ZenohSink {
    session: Session,
    domain: u32,
    zid: String,
    publishers: BTreeMap<String, ZenohPublisher>,
    next_entity: u32,
    _node_token: LivelinessToken,
}

/// DDS writers, one per topic (each a `dds::Writer` of its topic's message), made on first use.
struct DdsSink {
    dds: Dds,
    writers: BTreeMap<String, Box<dyn Any + Send>>,
}

enum Sink {
    Zenoh(ZenohSink),
    Dds(Box<DdsSink>),
}

struct Output {
    sink: Sink,
    /// Counts samples published (`conesight_frames_processed_total`) and what was not
    /// (`conesight_errors_total{kind="ros2_output"}`).
    node: Node,
}

impl ZenohSink {
    async fn publish<M: RosMessage>(&mut self, topic: &str, message: &M) -> anyhow::Result<()> {
        let payload = conesight_ros2::to_cdr(message)?;
        if !self.publishers.contains_key(topic) {
            self.next_entity += 1;
            let token_key = rmw_zenoh::publisher_token::<M>(
                self.domain,
                &self.zid,
                0,
                self.next_entity,
                NODE,
                topic,
            );
            let token = self
                .session
                .liveliness()
                .declare_token(token_key.clone())
                .await
                .map_err(|e| anyhow::anyhow!("declaring {token_key}: {e}"))?;
            self.publishers.insert(
                topic.to_owned(),
                ZenohPublisher {
                    key: rmw_zenoh::data_key::<M>(self.domain, topic),
                    gid: rmw_zenoh::gid(&self.zid, topic),
                    sequence: 0,
                    _token: token,
                },
            );
        }
        let Some(publisher) = self.publishers.get_mut(topic) else {
            return Ok(());
        };
        publisher.sequence += 1;
        let attachment = rmw_zenoh::attachment(
            publisher.sequence,
            i64::try_from(now_ns()).unwrap_or(i64::MAX),
            &publisher.gid,
        );
        self.session
            .put(publisher.key.clone(), payload)
            .attachment(attachment.to_vec())
            .await
            .map_err(|e| anyhow::anyhow!("publishing {}: {e}", publisher.key))
    }
}

impl DdsSink {
    /// Writes `message` on `topic` with the topic's writer, made on first use.
    async fn write<M: DdsMessage + 'static>(
        &mut self,
        topic: &str,
        message: M,
    ) -> anyhow::Result<()> {
        if !self.writers.contains_key(topic) {
            let writer = self.dds.writer::<M>(topic).await?;
            self.writers.insert(topic.to_owned(), Box::new(writer));
        }
        let writer = self
            .writers
            .get(topic)
            .and_then(|w| w.downcast_ref::<dds::Writer<M>>())
            .with_context(|| format!("{topic} carries another type than {}", M::TYPE))?;
        Ok(writer.write(message).await?)
    }
}

impl Output {
    async fn publish<M: DdsMessage + 'static>(
        &mut self,
        topic: &str,
        message: M,
    ) -> anyhow::Result<()> {
        match &mut self.sink {
            Sink::Zenoh(sink) => sink.publish(topic, &message).await?,
            Sink::Dds(sink) => sink.write(topic, message).await?,
        }
        self.node.metrics.frame_processed();
        Ok(())
    }
}

/// How `serve` reaches ROS 2.
#[derive(Debug, Clone)]
pub struct Ros2Settings {
    /// The middleware.
    pub rmw: Rmw,
    /// `--dds-interface`: the network interface DDS is confined to (DDS only).
    pub dds_interface: Option<String>,
}

/// The sink of `settings`, and a line for the logs saying where the topics go.
async fn open_sink(session: &Session, settings: &Ros2Settings) -> anyhow::Result<(Sink, String)> {
    let domain = rmw_zenoh::domain_from_env().map_err(anyhow::Error::msg)?;
    Ok(match settings.rmw {
        Rmw::Zenoh => {
            let zid = session.zid().to_string();
            let node_token = session
                .liveliness()
                .declare_token(rmw_zenoh::node_token(domain, &zid, 0, NODE))
                .await
                .map_err(|e| anyhow::anyhow!("declaring the ROS 2 node's liveliness token: {e}"))?;
            let sink = Sink::Zenoh(ZenohSink {
                session: session.clone(),
                domain,
                zid,
                publishers: BTreeMap::new(),
                next_entity: 0,
                _node_token: node_token,
            });
            (sink, format!("over rmw_zenoh (domain {domain})"))
        }
        Rmw::Dds => {
            let interface = dds::interface_from_env(settings.dds_interface.as_deref())?;
            let dds = dds::open(domain, interface.as_deref())
                .await
                .context("joining the ROS 2 domain over DDS")?;
            let sink = Sink::Dds(Box::new(DdsSink {
                dds,
                writers: BTreeMap::new(),
            }));
            let on = interface.map_or_else(
                || "every interface".to_owned(),
                |i| format!("interface {i}"),
            );
            (sink, format!("over DDS (domain {domain}, {on})"))
        }
    })
}

/// Starts publishing the run's cones and calibration as ROS 2 topics (`settings`) until
/// `shutdown`, counting on `node`.
pub async fn serve(
    session: &Session,
    topics: &Topics,
    settings: &Ros2Settings,
    node: &Node,
    shutdown: &Shutdown,
) -> anyhow::Result<String> {
    let (sink, description) = open_sink(session, settings).await?;
    let cones = declare_subscriber(session, topics.all_cameras(Stream::Cones)?, Stream::Cones)
        .await
        .context("subscribing to the cones")?;
    let keypoints = declare_subscriber(
        session,
        topics.all_cameras(Stream::Keypoints)?,
        Stream::Keypoints,
    )
    .await?;
    let infos = declare_subscriber(
        session,
        topics.all_cameras(Stream::CameraInfo)?,
        Stream::CameraInfo,
    )
    .await?;
    let mut output = Output {
        sink,
        node: node.clone(),
    };
    let shutdown = shutdown.clone();
    tokio::spawn(async move {
        let mut kept: BTreeMap<String, VecDeque<(u64, Vec<ConeKeypoints>)>> = BTreeMap::new();
        loop {
            let result = tokio::select! {
                () = shutdown.wait() => break,
                sample = cones.recv_async() => match sample {
                    Ok(sample) => on_cones(&mut output, &kept, sample.payload()).await,
                    Err(_) => break,
                },
                sample = keypoints.recv_async() => match sample {
                    Ok(sample) => {
                        keep_keypoints(&mut kept, sample.payload());
                        Ok(())
                    }
                    Err(_) => break,
                },
                sample = infos.recv_async() => match sample {
                    Ok(sample) => on_camera_info(&mut output, sample.payload()).await,
                    Err(_) => break,
                },
            };
            if let Err(error) = result {
                output.node.errors.report(
                    "ros2_output",
                    &format!("ROS 2 output: not published: {error:#}"),
                );
            }
        }
    });
    Ok(description)
}

/// Arguments of `conesight ros2`.
#[derive(Debug, clap::Args)]
pub struct Ros2Args {
    /// Zenoh session and keys: `--namespace` and `--vehicle` name the run whose cones go out.
    #[command(flatten)]
    zenoh: conesight_bus::ZenohArgs,
    /// Serve /livez, /readyz and /metrics here.
    #[arg(long = "http-addr", default_value = "127.0.0.1:9094")]
    http_addr: std::net::SocketAddr,
    /// The ROS 2 middleware: `dds` (Cyclone DDS, Fast DDS) or `zenoh` (rmw_zenoh).
    #[arg(long, value_enum, default_value = "dds")]
    rmw: Rmw,
    /// DDS only: the network interface to use (e.g. `eth0`). Default: `lo` under
    /// `ROS_LOCALHOST_ONLY=1` or `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`, else every interface.
    #[arg(long = "dds-interface")]
    dds_interface: Option<String>,
}

/// `conesight ros2`: the ROS 2 output as a service of its own on the bus (liveliness token,
/// health and manifest queries, HTTP health and metrics), until Ctrl-C.
pub fn run(args: &Ros2Args) -> anyhow::Result<()> {
    conesight_service::init_tracing();
    crate::async_runtime()?.block_on(async {
        let shutdown = Shutdown::new();
        shutdown.trigger_on_signal();
        let session = conesight_bus::open_session(&args.zenoh).await?;
        let topics = Topics::from_args(&args.zenoh)?;
        let node = Node::new("ros2", "*", session.clone(), topics.clone(), None);
        let bound = node.serve_http(args.http_addr, &shutdown).await?;
        let _presence = node.announce().await?;
        let settings = Ros2Settings {
            rmw: args.rmw,
            dds_interface: args.dds_interface.clone(),
        };
        let description = serve(&session, &topics, &settings, &node, &shutdown).await?;
        eprintln!(
            "ros2: the cones of conesight/{}/** as ROS 2 topics {}; metrics on \
             http://{bound}/metrics (Ctrl-C stops)",
            topics.namespace(),
            description
        );
        shutdown.wait().await;
        let _ = session.close().await;
        Ok(())
    })
}

fn keep_keypoints(
    kept: &mut BTreeMap<String, VecDeque<(u64, Vec<ConeKeypoints>)>>,
    payload: &conesight_bus::zenoh::bytes::ZBytes,
) {
    let Ok(message) = decode::<pb::Keypoints>(payload) else {
        return;
    };
    let (Some(header), Ok(keypoints)) = (message.header.clone(), message.to_core()) else {
        return;
    };
    let ring = kept.entry(header.camera_id).or_default();
    ring.push_back((header.frame_sequence, keypoints));
    while ring.len() > KEYPOINTS_KEPT {
        ring.pop_front();
    }
}

async fn on_cones(
    output: &mut Output,
    kept: &BTreeMap<String, VecDeque<(u64, Vec<ConeKeypoints>)>>,
    payload: &conesight_bus::zenoh::bytes::ZBytes,
) -> anyhow::Result<()> {
    let message = decode::<pb::Cones>(payload)?;
    let header = conesight_proto::require_header(&message.header)?.clone();
    let cones = message.to_core()?;
    let keypoints = kept
        .get(&header.camera_id)
        .and_then(|ring| ring.iter().rev().find(|(s, _)| *s == header.frame_sequence))
        .map(|(_, k)| k.as_slice())
        .unwrap_or_default();
    let array = conesight_ros2::convert::cone_array(&header, &cones, keypoints);
    let topic = conesight_ros2::bag::topic(&header.camera_id, "cones");
    let markers = conesight_ros2::convert::cone_markers(&array, &header.camera_id);
    output.publish(&topic, array).await?;
    let topic = conesight_ros2::bag::topic(&header.camera_id, "cone_markers");
    output.publish(&topic, markers).await
}

async fn on_camera_info(
    output: &mut Output,
    payload: &conesight_bus::zenoh::bytes::ZBytes,
) -> anyhow::Result<()> {
    let info = decode::<pb::CameraInfo>(payload)?;
    let header = conesight_proto::require_header(&info.header)?.clone();
    let (camera, _) = info.to_core()?;
    let ros = conesight_ros2::convert::camera_info(&header, &camera);
    let topic = conesight_ros2::bag::topic(&header.camera_id, "camera_info");
    output.publish(&topic, ros).await
}
