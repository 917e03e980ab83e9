//! ROS 2 over DDS: the topics a ROS 2 node on Cyclone DDS or Fast DDS sees, with Dust DDS.
//!
//! **Why Dust DDS.** It is a maintained, pure-Rust DDS (RTPS 2.5, no unsafe code) whose
//! transport is pluggable. RustDDS (under `ros2-client`) was the other candidate; its UDP
//! transport cannot be bound to one network interface (its `only_networks` setting is a
//! placeholder), so it multicasts discovery on every interface, which neither `ROS_LOCALHOST_ONLY`
//! nor our tests may do. Dust DDS's own UDP transport picks its locators and multicast group on a
//! named interface but still sends multicast out of every interface, so [`open`] wraps it:
//! with an interface (`--dds-interface`, or `lo` under `ROS_LOCALHOST_ONLY=1` /
//! `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`), every datagram leaves from a socket bound to that
//! interface's address ([`InterfaceTransport`]).
//!
//! **What ROS 2 expects** (rmw_cyclonedds and rmw_fastrtps alike): topic `rt<topic>`
//! (`rt/conesight/cam/cones`), type `<package>::msg::dds_::<Type>_`, CDR (XCDR1, little
//! endian) in the `.msg` field order, domain `ROS_DOMAIN_ID`. Publishers are reliable, volatile,
//! keep-last 10 (ROS 2's default QoS); [`Dds::subscribe`] reads best-effort (why there), so a
//! camera driver's reliable or best-effort publisher matches alike.
//!
//! Dust DDS drops a received sample that does not decode as its type (a peer with another
//! definition under the same name) without reporting it: such samples cannot be counted here.
//!
//! Dust DDS 0.15 serialises arrays of structures but not of `float64`, and reads arrays of
//! `float64` but not of structures; the messages with `float64[N]` fields (`CameraInfo`,
//! `Cone`) therefore cross the wire as the mirrors below, whose fixed arrays are structures of
//! N `float64` members: the same bytes in XCDR1.

use std::net::{Ipv4Addr, SocketAddrV4, UdpSocket};
use std::pin::Pin;
use std::sync::Arc;

use dust_dds::dcps::channels::mpsc::MpscSender;
use dust_dds::dds_async::data_reader::DataReaderAsync;
use dust_dds::dds_async::data_reader_listener::DataReaderListener;
use dust_dds::dds_async::data_writer::DataWriterAsync;
use dust_dds::dds_async::domain_participant::DomainParticipantAsync;
use dust_dds::dds_async::domain_participant_factory::DomainParticipantFactoryAsync;
use dust_dds::dds_async::publisher::PublisherAsync;
use dust_dds::dds_async::subscriber::SubscriberAsync;
use dust_dds::infrastructure::qos::{DataReaderQos, DataWriterQos, QosKind};
use dust_dds::infrastructure::qos_policy::{
    DurabilityQosPolicy, DurabilityQosPolicyKind, HistoryQosPolicy, HistoryQosPolicyKind,
    ReliabilityQosPolicy, ReliabilityQosPolicyKind,
};
use dust_dds::infrastructure::sample_info::{ANY_INSTANCE_STATE, ANY_SAMPLE_STATE, ANY_VIEW_STATE};
use dust_dds::infrastructure::status::{NO_STATUS, StatusKind};
use dust_dds::infrastructure::time::{Duration as DdsDuration, DurationKind};
use dust_dds::infrastructure::type_support::{DdsType, TypeSupport};
use dust_dds::listener::NO_LISTENER;
use dust_dds::rtps_udp_transport::udp_transport::{
    RtpsUdpTransportParticipantFactory, RtpsUdpTransportParticipantFactoryBuilder,
};
use dust_dds::std_runtime::StdRuntime;
use dust_dds::std_runtime::executor::Executor;
use dust_dds::std_runtime::timer::TimerDriver;
use dust_dds::transport::interface::{
    RtpsTransportParticipant, TransportParticipantFactory, WriteMessage,
};
use dust_dds::transport::types::{LOCATOR_KIND_UDP_V4, Locator};

use crate::Ros2Error;

use crate::msg::{self, Header, Keypoint, Point, RegionOfInterest, RosMessage};
/// Runs a DDS future to completion on this thread (for callers outside an async runtime).
pub use dust_dds::std_runtime::executor::block_on;

/// `rt/conesight/cam/cones` for ROS 2 topic `/conesight/cam/cones`.
pub fn dds_topic(topic: &str) -> String {
    format!("rt/{}", topic.trim_start_matches('/'))
}

/// The interface DDS is confined to: `flag` (`--dds-interface`) when given, else `lo` when
/// `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` or `ROS_LOCALHOST_ONLY=1` (as ROS 2 reads them),
/// else none (every interface, ROS 2's default). `ROS_AUTOMATIC_DISCOVERY_RANGE=OFF` is refused:
/// a DDS participant that discovers nothing publishes to no one.
pub fn interface_from_env(flag: Option<&str>) -> Result<Option<String>, Ros2Error> {
    let invalid = |reason: String| Ros2Error::Invalid {
        type_name: "DDS",
        reason,
    };
    if let Some(name) = flag.map(str::trim).filter(|n| !n.is_empty()) {
        return Ok(Some(name.to_owned()));
    }
    let range = std::env::var("ROS_AUTOMATIC_DISCOVERY_RANGE").unwrap_or_default();
    match range.trim().to_ascii_uppercase().as_str() {
        "LOCALHOST" => return Ok(Some("lo".to_owned())),
        "OFF" => {
            return Err(invalid(
                "ROS_AUTOMATIC_DISCOVERY_RANGE=OFF: nothing would be discovered; unset it, or set \
                 LOCALHOST or SUBNET"
                    .to_owned(),
            ));
        }
        "" | "SUBNET" | "SYSTEM_DEFAULT" => {}
        other => {
            return Err(invalid(format!(
                "ROS_AUTOMATIC_DISCOVERY_RANGE={other}: use LOCALHOST, SUBNET, SYSTEM_DEFAULT or \
                 OFF"
            )));
        }
    }
    Ok((std::env::var("ROS_LOCALHOST_ONLY").as_deref() == Ok("1")).then(|| "lo".to_owned()))
}

/// The IPv4 address of interface `name`.
fn interface_address(name: &str) -> Result<Ipv4Addr, Ros2Error> {
    use network_interface::{Addr, NetworkInterface, NetworkInterfaceConfig};
    let invalid = |reason: String| Ros2Error::Invalid {
        type_name: "DDS",
        reason,
    };
    let interfaces =
        NetworkInterface::show().map_err(|e| invalid(format!("listing interfaces: {e}")))?;
    let names: Vec<String> = interfaces.iter().map(|i| i.name.clone()).collect();
    interfaces
        .into_iter()
        .filter(|i| i.name == name)
        .flat_map(|i| i.addr)
        .find_map(|a| match a {
            Addr::V4(v4) => Some(v4.ip),
            Addr::V6(_) => None,
        })
        .ok_or_else(|| {
            invalid(format!(
                "network interface `{name}` has no IPv4 address (interfaces here: {}); give \
                 --dds-interface one of them",
                names.join(", ")
            ))
        })
}

/// Dust DDS's UDP transport with every datagram sent from `address` (module docs).
struct InterfaceTransport {
    inner: RtpsUdpTransportParticipantFactory,
    address: Ipv4Addr,
}

struct InterfaceWriter {
    socket: UdpSocket,
}

impl WriteMessage for InterfaceWriter {
    fn write_message(
        &self,
        datagram: &[u8],
        locators: &[Locator],
    ) -> Pin<Box<dyn Future<Output = ()> + Send>> {
        for locator in locators.iter().filter(|l| l.kind() == LOCATOR_KIND_UDP_V4) {
            let a = locator.address();
            let Ok(port) = u16::try_from(locator.port()) else {
                continue;
            };
            let to = SocketAddrV4::new(Ipv4Addr::new(a[12], a[13], a[14], a[15]), port);
            // UDP: a datagram that does not leave is lost, as on the wire; reliable
            // writers resend it.
            let _ = self.socket.send_to(datagram, to);
        }
        Box::pin(std::future::ready(()))
    }
}

impl TransportParticipantFactory for InterfaceTransport {
    async fn create_participant(
        &self,
        domain_id: i32,
        data_channel_sender: MpscSender<Arc<[u8]>>,
    ) -> RtpsTransportParticipant {
        let mut participant = self
            .inner
            .create_participant(domain_id, data_channel_sender)
            .await;
        match interface_socket(self.address) {
            Ok(socket) => participant.message_writer = Box::new(InterfaceWriter { socket }),
            // Checked in `open` before the factory exists; kept as is if it fails now.
            Err(error) => tracing::error!("DDS: a socket on {}: {error}", self.address),
        }
        participant
    }
}

fn interface_socket(address: Ipv4Addr) -> std::io::Result<UdpSocket> {
    let socket = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::DGRAM, None)?;
    socket.bind(&std::net::SocketAddr::from((address, 0)).into())?;
    socket.set_multicast_if_v4(&address)?;
    socket.set_multicast_loop_v4(true)?;
    Ok(socket.into())
}

/// The user-data socket's receive buffer: a 1920x1200 bgr8 image is 6.9 MB in ~5,100
/// fragments. Linux caps it at `net.core.rmem_max` (raise that on the car, as for any DDS
/// carrying raw images): an image whose fragments overflow it is lost.
const RECEIVE_BUFFER_BYTES: usize = 16 << 20;

/// A DDS domain participant of ROS 2 domain `domain` with one publisher and one subscriber.
pub struct Dds {
    // Kept for the participant's lifetime.
    _factory: DomainParticipantFactoryAsync<StdRuntime>,
    participant: DomainParticipantAsync,
    publisher: PublisherAsync,
    subscriber: SubscriberAsync,
}

fn dds_error(what: &str, error: impl std::fmt::Debug) -> Ros2Error {
    Ros2Error::Invalid {
        type_name: "DDS",
        reason: format!("{what}: {error:?}"),
    }
}

/// Joins ROS 2 domain `domain` over DDS, on `interface` only when given (see
/// [`interface_from_env`]).
pub async fn open(domain: u32, interface: Option<&str>) -> Result<Dds, Ros2Error> {
    if domain > 232 {
        return Err(Ros2Error::Invalid {
            type_name: "DDS",
            reason: format!("ROS_DOMAIN_ID={domain}: DDS domains go from 0 to 232"),
        });
    }
    let runtime = StdRuntime::new(Executor::new(), TimerDriver::new());
    // The GUID prefix is host id, app id and a per-factory counter: two factories in one
    // process (a ROS 2 camera source and the ROS 2 output) need app ids of their own, or
    // their participants share a GUID and peers take them for one.
    static FACTORIES: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let factory_index = FACTORIES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let app_id = (std::process::id() ^ (factory_index << 24)).to_be_bytes();
    let factory = match interface {
        Some(name) => {
            let address = interface_address(name)?;
            interface_socket(address)
                .map_err(|e| dds_error(&format!("a UDP socket on {name} ({address})"), e))?;
            let inner = RtpsUdpTransportParticipantFactoryBuilder::new()
                .interface_name(Some(name.to_owned()))
                .udp_receive_buffer_size(Some(RECEIVE_BUFFER_BYTES))
                .build()
                .map_err(|e| dds_error("the UDP transport", e))?;
            DomainParticipantFactoryAsync::new(
                runtime,
                app_id,
                address.octets(),
                InterfaceTransport { inner, address },
            )
        }
        None => {
            let host = random_host_id();
            let transport = RtpsUdpTransportParticipantFactoryBuilder::new()
                .udp_receive_buffer_size(Some(RECEIVE_BUFFER_BYTES))
                .build()
                .map_err(|e| dds_error("the UDP transport", e))?;
            DomainParticipantFactoryAsync::new(runtime, app_id, host, transport)
        }
    };
    let participant = factory
        .create_participant(domain as i32, QosKind::Default, NO_LISTENER, NO_STATUS)
        .await
        .map_err(|e| dds_error("creating the domain participant", e))?;
    let publisher = participant
        .create_publisher(QosKind::Default, NO_LISTENER, NO_STATUS)
        .await
        .map_err(|e| dds_error("creating the publisher", e))?;
    let subscriber = participant
        .create_subscriber(QosKind::Default, NO_LISTENER, NO_STATUS)
        .await
        .map_err(|e| dds_error("creating the subscriber", e))?;
    Ok(Dds {
        _factory: factory,
        participant,
        publisher,
        subscriber,
    })
}

/// Four bytes that set this process's participants apart from other hosts' (the GUID prefix's
/// host part) when no interface address names the host.
fn random_host_id() -> [u8; 4] {
    use std::hash::{BuildHasher, Hasher};
    let mut hasher = std::collections::hash_map::RandomState::new().build_hasher();
    hasher.write_u32(std::process::id());
    (hasher.finish() as u32).to_be_bytes()
}

/// A ROS 2 message that crosses DDS as `Wire`.
pub trait DdsMessage: RosMessage + Sized {
    /// Its DDS form.
    type Wire: TypeSupport + Send + Sync + 'static;
    /// To the DDS form.
    fn to_wire(self) -> Self::Wire;
    /// From the DDS form.
    fn from_wire(wire: Self::Wire) -> Self;
}

macro_rules! same_on_the_wire {
    ($($t:ty),*) => {$(
        impl DdsMessage for $t {
            type Wire = $t;
            fn to_wire(self) -> Self { self }
            fn from_wire(wire: Self) -> Self { wire }
        }
    )*};
}
same_on_the_wire!(msg::Image, msg::CompressedImage, msg::MarkerArray);

/// A DDS writer of ROS 2 messages `M` on one topic.
pub struct Writer<M: DdsMessage> {
    writer: DataWriterAsync<M::Wire>,
}

impl<M: DdsMessage> Writer<M> {
    /// Publishes `message`.
    pub async fn write(&self, message: M) -> Result<(), Ros2Error> {
        self.writer
            .write(message.to_wire(), None)
            .await
            .map_err(|e| dds_error(&format!("writing {}", M::TYPE), e))
    }
}

/// Calls its closure with each message a reader takes.
struct Forward<M, F> {
    on_message: F,
    _message: std::marker::PhantomData<fn() -> M>,
}

impl<M, F> DataReaderListener<M::Wire> for Forward<M, F>
where
    M: DdsMessage + 'static,
    F: FnMut(M) + Send + 'static,
{
    async fn on_data_available(&mut self, reader: DataReaderAsync<M::Wire>) {
        let Ok(samples) = reader
            .take(16, ANY_SAMPLE_STATE, ANY_VIEW_STATE, ANY_INSTANCE_STATE)
            .await
        else {
            return;
        };
        for sample in samples {
            if let Some(data) = sample.data {
                (self.on_message)(M::from_wire(data));
            }
        }
    }
}

impl Dds {
    async fn topic<M: DdsMessage>(
        &self,
        topic: &str,
    ) -> Result<dust_dds::dds_async::topic_description::TopicDescriptionAsync, Ros2Error> {
        self.participant
            .create_topic::<M::Wire>(
                &dds_topic(topic),
                &crate::rmw_zenoh::dds_type_name(M::TYPE),
                QosKind::Default,
                NO_LISTENER,
                NO_STATUS,
            )
            .await
            .map_err(|e| dds_error(&format!("creating topic {topic}"), e))
    }

    /// A writer of `M` on ROS 2 topic `topic` (`/conesight/cam/cones`) with ROS 2's default
    /// QoS: reliable, volatile, keep-last 10.
    pub async fn writer<M: DdsMessage>(&self, topic: &str) -> Result<Writer<M>, Ros2Error> {
        let topic_handle = self.topic::<M>(topic).await?;
        let qos = DataWriterQos {
            reliability: ReliabilityQosPolicy {
                kind: ReliabilityQosPolicyKind::Reliable,
                max_blocking_time: DurationKind::Finite(DdsDuration::new(0, 100_000_000)),
            },
            durability: DurabilityQosPolicy {
                kind: DurabilityQosPolicyKind::Volatile,
            },
            history: HistoryQosPolicy {
                kind: HistoryQosPolicyKind::KeepLast(10),
            },
            ..Default::default()
        };
        let writer = self
            .publisher
            .create_datawriter::<M::Wire>(
                &topic_handle,
                QosKind::Specific(qos),
                NO_LISTENER,
                NO_STATUS,
            )
            .await
            .map_err(|e| dds_error(&format!("creating a writer on {topic}"), e))?;
        Ok(Writer { writer })
    }

    /// Calls `on_message` with each `M` on ROS 2 topic `topic`, read best-effort, keep-last 1
    /// (ROS 2's sensor data QoS: it matches reliable and best-effort publishers alike).
    ///
    /// Not reliable: Dust DDS 0.15's reliable reader panics (its executor thread, and with it
    /// every DDS reader and writer of the process) when it asks for more than 256 lost fragments
    /// of one sample (`FragmentNumberSet::new`), which a 1.7 MB image that lost its tail does.
    /// Best-effort, an image that loses a fragment is dropped and the next one taken.
    pub async fn subscribe<M, F>(&self, topic: &str, on_message: F) -> Result<(), Ros2Error>
    where
        M: DdsMessage + 'static,
        F: FnMut(M) + Send + 'static,
    {
        let topic_handle = self.topic::<M>(topic).await?;
        let qos = DataReaderQos {
            reliability: ReliabilityQosPolicy {
                kind: ReliabilityQosPolicyKind::BestEffort,
                max_blocking_time: DurationKind::Finite(DdsDuration::new(0, 100_000_000)),
            },
            history: HistoryQosPolicy {
                kind: HistoryQosPolicyKind::KeepLast(1),
            },
            ..Default::default()
        };
        let listener = Forward::<M, F> {
            on_message,
            _message: std::marker::PhantomData,
        };
        self.subscriber
            .create_datareader::<M::Wire>(
                &topic_handle,
                QosKind::Specific(qos),
                Some(listener),
                &[StatusKind::DataAvailable],
            )
            .await
            .map_err(|e| dds_error(&format!("subscribing to {topic}"), e))?;
        Ok(())
    }
}

/// `float64[9]` on the wire (module docs).
#[derive(Debug, Clone, Copy, Default, DdsType)]
pub struct F64x9 {
    v0: f64,
    v1: f64,
    v2: f64,
    v3: f64,
    v4: f64,
    v5: f64,
    v6: f64,
    v7: f64,
    v8: f64,
}

impl From<[f64; 9]> for F64x9 {
    fn from(v: [f64; 9]) -> Self {
        let [v0, v1, v2, v3, v4, v5, v6, v7, v8] = v;
        Self {
            v0,
            v1,
            v2,
            v3,
            v4,
            v5,
            v6,
            v7,
            v8,
        }
    }
}

impl From<F64x9> for [f64; 9] {
    fn from(v: F64x9) -> Self {
        [v.v0, v.v1, v.v2, v.v3, v.v4, v.v5, v.v6, v.v7, v.v8]
    }
}

/// `float64[12]` on the wire: a 3x3 block and a column.
#[derive(Debug, Clone, Copy, Default, DdsType)]
pub struct F64x12 {
    head: F64x9,
    t0: f64,
    t1: f64,
    t2: f64,
}

impl From<[f64; 12]> for F64x12 {
    fn from(v: [f64; 12]) -> Self {
        let head: [f64; 9] = std::array::from_fn(|i| v[i]);
        Self {
            head: head.into(),
            t0: v[9],
            t1: v[10],
            t2: v[11],
        }
    }
}

impl From<F64x12> for [f64; 12] {
    fn from(v: F64x12) -> Self {
        let head: [f64; 9] = v.head.into();
        std::array::from_fn(|i| {
            if i < 9 {
                head[i]
            } else {
                [v.t0, v.t1, v.t2][i - 9]
            }
        })
    }
}

/// `sensor_msgs/msg/CameraInfo` on the wire.
#[derive(Debug, Clone, Default, DdsType)]
pub struct CameraInfoWire {
    header: Header,
    height: u32,
    width: u32,
    distortion_model: String,
    d: Vec<f64>,
    k: F64x9,
    r: F64x9,
    p: F64x12,
    binning_x: u32,
    binning_y: u32,
    roi: RegionOfInterest,
}

/// `$target { a: $src.a, .., k: $src.k.into(), .. }`: a message and its wire mirror share
/// their field names; the fixed arrays convert.
macro_rules! move_fields {
    ($src:expr => $target:path { $($same:ident),* ; $($converted:ident),* }) => {{
        let src = $src;
        $target { $($same: src.$same,)* $($converted: src.$converted.into(),)* }
    }};
}

impl DdsMessage for msg::CameraInfo {
    type Wire = CameraInfoWire;
    fn to_wire(self) -> CameraInfoWire {
        move_fields!(self => CameraInfoWire {
            header, height, width, distortion_model, d, binning_x, binning_y, roi; k, r, p
        })
    }
    fn from_wire(w: CameraInfoWire) -> Self {
        move_fields!(w => Self {
            header, height, width, distortion_model, d, binning_x, binning_y, roi; k, r, p
        })
    }
}

/// `conesight_msgs/msg/Cone` on the wire.
#[derive(Debug, Clone, Default, DdsType)]
pub struct ConeWire {
    cone_class: u8,
    score: f32,
    position: Point,
    covariance: F64x9,
    position_in_camera: Point,
    range_m: f64,
    ranging: u8,
    reprojection_rms_px: f64,
    tilt_rad: f64,
    keypoints: Vec<Keypoint>,
    box_x_min_px: f32,
    box_y_min_px: f32,
    box_x_max_px: f32,
    box_y_max_px: f32,
}

/// `conesight_msgs/msg/ConeArray` on the wire.
#[derive(Debug, Clone, Default, DdsType)]
pub struct ConeArrayWire {
    header: Header,
    camera_frame_id: String,
    frame_sequence: u64,
    cones: Vec<ConeWire>,
}

impl DdsMessage for msg::ConeArray {
    type Wire = ConeArrayWire;
    fn to_wire(self) -> ConeArrayWire {
        ConeArrayWire {
            header: self.header,
            camera_frame_id: self.camera_frame_id,
            frame_sequence: self.frame_sequence,
            cones: self
                .cones
                .into_iter()
                .map(|c| {
                    move_fields!(c => ConeWire {
                        cone_class, score, position, position_in_camera, range_m, ranging,
                        reprojection_rms_px, tilt_rad, keypoints, box_x_min_px, box_y_min_px,
                        box_x_max_px, box_y_max_px; covariance
                    })
                })
                .collect(),
        }
    }
    fn from_wire(w: ConeArrayWire) -> Self {
        Self {
            header: w.header,
            camera_frame_id: w.camera_frame_id,
            frame_sequence: w.frame_sequence,
            cones: w
                .cones
                .into_iter()
                .map(|c| {
                    move_fields!(c => msg::Cone {
                        cone_class, score, position, position_in_camera, range_m, ranging,
                        reprojection_rms_px, tilt_rad, keypoints, box_x_min_px, box_y_min_px,
                        box_x_max_px, box_y_max_px; covariance
                    })
                })
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_arrays_round_trip_through_their_wire_structures() {
        let nine: [f64; 9] = std::array::from_fn(|i| i as f64 + 0.5);
        assert_eq!(<[f64; 9]>::from(F64x9::from(nine)), nine);
        let twelve: [f64; 12] = std::array::from_fn(|i| i as f64 * 2.0);
        assert_eq!(<[f64; 12]>::from(F64x12::from(twelve)), twelve);
    }

    #[test]
    fn messages_round_trip_through_their_wire_mirrors() {
        let cone = msg::Cone {
            cone_class: 4,
            score: 0.5,
            covariance: std::array::from_fn(|i| i as f64),
            range_m: 12.5,
            keypoints: vec![msg::Keypoint::default(); 7],
            box_y_max_px: 3.0,
            ..Default::default()
        };
        let array = msg::ConeArray {
            camera_frame_id: "cam".to_owned(),
            frame_sequence: 9,
            cones: vec![cone],
            ..Default::default()
        };
        assert_eq!(msg::ConeArray::from_wire(array.clone().to_wire()), array);
        let info = msg::CameraInfo {
            width: 1920,
            d: vec![0.1, 0.2],
            p: std::array::from_fn(|i| i as f64 + 1.0),
            ..Default::default()
        };
        assert_eq!(msg::CameraInfo::from_wire(info.clone().to_wire()), info);
    }

    #[test]
    fn topics_are_prefixed_rt() {
        assert_eq!(dds_topic("/conesight/cam/cones"), "rt/conesight/cam/cones");
    }

    #[test]
    fn an_interface_that_does_not_exist_is_named_with_the_ones_that_do() {
        let error = interface_address("no-such-if0").unwrap_err().to_string();
        assert!(
            error.contains("no-such-if0") && error.contains("lo"),
            "{error}"
        );
        assert_eq!(interface_address("lo").unwrap(), Ipv4Addr::LOCALHOST);
    }

    #[test]
    fn domains_past_232_are_refused() {
        let error = dust_dds::std_runtime::executor::block_on(open(233, Some("lo")))
            .err()
            .unwrap()
            .to_string();
        assert!(error.contains("232"), "{error}");
    }
}
