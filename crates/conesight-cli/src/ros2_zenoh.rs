//! `conesight run --ros2 zenoh`: the run's cones and calibration as ROS 2 topics in rmw_zenoh's
//! format on the run's own Zenoh session (`conesight_ros2::rmw_zenoh` has the formats):
//! `/conesight/<camera>/cones` (`conesight_msgs/msg/ConeArray`, each cone with its keypoints
//! from the same frame's keypoints message), `/conesight/<camera>/cone_markers`
//! (`visualization_msgs/msg/MarkerArray`, for RViz) and `/conesight/<camera>/camera_info`
//! (`sensor_msgs/msg/CameraInfo`), published by node `conesight` on `ROS_DOMAIN_ID` (0 when
//! unset). A message that does not convert is logged (rate-limited) and not published.

use std::collections::{BTreeMap, VecDeque};

use anyhow::Context;
use conesight_bus::zenoh::Session;
use conesight_bus::zenoh::liveliness::LivelinessToken;
use conesight_bus::{Stream, Topics, declare_subscriber, decode};
use conesight_pipeline::{Node, Shutdown};
use conesight_proto::{ConeKeypoints, now_ns, pb};
use conesight_ros2::msg::{CameraInfo, ConeArray, MarkerArray, RosMessage};
use conesight_ros2::rmw_zenoh;

/// The ROS 2 node's name.
const NODE: &str = "conesight";
/// Keypoints messages kept per camera to give each cone its keypoints.
const KEYPOINTS_KEPT: usize = 32;

/// One ROS 2 publisher: its key, GID, sequence and liveliness token.
struct Publisher {
    key: String,
    gid: [u8; 16],
    sequence: i64,
    _token: LivelinessToken,
}

struct Output {
    session: Session,
    domain: u32,
    zid: String,
    publishers: BTreeMap<String, Publisher>,
    next_entity: u32,
    /// Counts samples published (`conesight_frames_processed_total`) and what was not
    /// (`conesight_errors_total{kind="ros2_output"}`).
    node: Node,
}

impl Output {
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
                Publisher {
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
            .map_err(|e| anyhow::anyhow!("publishing {}: {e}", publisher.key))?;
        self.node.metrics.frame_processed();
        Ok(())
    }
}

/// Starts publishing the run's cones and calibration as ROS 2 topics over rmw_zenoh until
/// `shutdown`, counting on `node`.
pub async fn serve(
    session: &Session,
    topics: &Topics,
    node: &Node,
    shutdown: &Shutdown,
) -> anyhow::Result<()> {
    let domain = rmw_zenoh::domain_from_env().map_err(anyhow::Error::msg)?;
    let zid = session.zid().to_string();
    let node_token = session
        .liveliness()
        .declare_token(rmw_zenoh::node_token(domain, &zid, 0, NODE))
        .await
        .map_err(|e| anyhow::anyhow!("declaring the ROS 2 node's liveliness token: {e}"))?;
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
        session: session.clone(),
        domain,
        zid,
        publishers: BTreeMap::new(),
        next_entity: 0,
        node: node.clone(),
    };
    let shutdown = shutdown.clone();
    tokio::spawn(async move {
        let _node_token = node_token;
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
    Ok(())
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
        serve(&session, &topics, &node, &shutdown).await?;
        eprintln!(
            "ros2: the cones of conesight/{}/** as ROS 2 topics over rmw_zenoh (domain {}); \
             metrics on http://{bound}/metrics (Ctrl-C stops)",
            topics.namespace(),
            rmw_zenoh::domain_from_env().unwrap_or(0)
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
    output.publish::<ConeArray>(&topic, &array).await?;
    let markers = conesight_ros2::convert::cone_markers(&array, &header.camera_id);
    let topic = conesight_ros2::bag::topic(&header.camera_id, "cone_markers");
    output.publish::<MarkerArray>(&topic, &markers).await
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
    output.publish::<CameraInfo>(&topic, &ros).await
}
