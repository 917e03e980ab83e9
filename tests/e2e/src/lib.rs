//! # conesight-e2e
//!
//! The harness of the end-to-end tests (`tests/`) and of the pipeline benchmark
//! (`src/bin/pipeline_bench.rs`): rendered fixtures with ground truth on disk ([`Fixture`]),
//! a cluster of service processes on loopback with explicit endpoints and free ports
//! ([`Cluster`]), an observer session collecting the cones ([`Observer`]) and a plain HTTP
//! scrape of `/metrics` ([`http_get`]).

use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::Context;
use conesight_bus::{Stream, Topics, ZenohArgs, declare_subscriber, decode, open_session};
use conesight_pipeline::boxes::kitti_line_of;
use conesight_pipeline::{
    SourceFrame, SyntheticParams, SyntheticSource, detector_is_trained, locate_detector,
};
use conesight_proto::{LocatedCone, now_ns, pb};

/// Held by every test that starts a [`Cluster`], so the tests of one binary (which cargo runs
/// in parallel) run their clusters one after another: on two cores, a restart timed while two
/// other clusters (one of them at a 3x overload) share the CPU measures the neighbours, not the
/// pipeline.
pub async fn one_cluster_at_a_time() -> tokio::sync::MutexGuard<'static, ()> {
    static CLUSTERS: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());
    CLUSTERS.lock().await
}

/// A free TCP port on 127.0.0.1, outside the ephemeral range (`conesight_bus::free_loopback_port`).
pub fn free_port() -> anyhow::Result<u16> {
    Ok(conesight_bus::free_loopback_port()?)
}

/// Rendered frames with exact truth, written as PNGs with KITTI label files and the camera's
/// calibration, for a camera service reading a folder.
#[derive(Debug)]
pub struct Fixture {
    /// The folder.
    pub dir: PathBuf,
    /// The frames, in file order (frame `i` is published as sequence `i`, `i + n`, ...).
    pub frames: Vec<SourceFrame>,
    /// ROS camera_info YAML.
    pub camera_yaml: PathBuf,
    /// Extrinsics YAML.
    pub extrinsics_yaml: PathBuf,
}

impl Fixture {
    /// Renders `count` frames of the default synthetic sequence into a fresh folder `name`
    /// under the system temp dir.
    pub fn render(name: &str, count: u64) -> anyhow::Result<Self> {
        let dir = std::env::temp_dir().join(format!("conesight-e2e-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir)?;
        let source = SyntheticSource::new(SyntheticParams::default())?;
        let frames = source.preload(count, false)?;
        for frame in &frames {
            let stem = format!("frame_{:04}", frame.index);
            frame.image.save(dir.join(format!("{stem}.png")))?;
            let labels: Vec<String> = frame
                .truth
                .as_ref()
                .map(|t| t.detections(false).iter().map(kitti_line_of).collect())
                .unwrap_or_default();
            std::fs::write(dir.join(format!("{stem}.txt")), labels.join("\n"))?;
        }
        let camera_yaml = dir.join("camera.yaml");
        std::fs::write(&camera_yaml, source.camera().to_ros_yaml("front"))?;
        let extrinsics_yaml = dir.join("extrinsics.yaml");
        std::fs::write(&extrinsics_yaml, source.extrinsics().to_yaml())?;
        Ok(Self {
            dir,
            frames,
            camera_yaml,
            extrinsics_yaml,
        })
    }

    /// The camera service's arguments to publish this folder at `rate_hz`, calibrated, looped.
    pub fn camera_args(&self, rate_hz: f64) -> Vec<String> {
        vec![
            "--source".to_owned(),
            "folder".to_owned(),
            "--images".to_owned(),
            self.dir.display().to_string(),
            "--camera-info".to_owned(),
            self.camera_yaml.display().to_string(),
            "--extrinsics".to_owned(),
            self.extrinsics_yaml.display().to_string(),
            "--rate-hz".to_owned(),
            rate_hz.to_string(),
            // The tests publish more frames than the folder holds.
            "--source-loop".to_owned(),
        ]
    }

    /// The frame published as `sequence`.
    pub fn frame(&self, sequence: u64) -> Option<&SourceFrame> {
        self.frames
            .get((sequence % self.frames.len().max(1) as u64) as usize)
    }
}

impl Drop for Fixture {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// The detector the tests use: the shipped one when trained, else none (the camera then
/// publishes the renderer's boxes).
pub fn trained_detector() -> Option<PathBuf> {
    let path = locate_detector(None);
    detector_is_trained(&path).then_some(path)
}

/// One service process of a [`Cluster`].
#[derive(Debug)]
struct Member {
    zenoh_port: u16,
    http_port: u16,
    extra: Vec<String>,
    child: Option<Child>,
}

/// Service processes on loopback: each listens on its own port and connects to every other
/// one (peer mode, explicit endpoints, multicast scouting off), in a namespace of its own.
#[derive(Debug)]
pub struct Cluster {
    exe: PathBuf,
    /// The run namespace.
    pub namespace: String,
    members: BTreeMap<String, Member>,
    /// Extra Zenoh port for an observer session.
    pub observer_port: u16,
    /// Per-node mTLS configs (`deploy/zenoh/mtls.sh`), when every link is `tls/`.
    mtls: Option<PathBuf>,
}

impl Cluster {
    /// A cluster of `services` (name, extra args), not started; `exe` is the
    /// `conesight-e2e-services` binary.
    pub fn new(
        exe: &Path,
        namespace: &str,
        services: &[(&str, Vec<String>)],
    ) -> anyhow::Result<Self> {
        let mut members = BTreeMap::new();
        for (name, extra) in services {
            members.insert(
                (*name).to_owned(),
                Member {
                    zenoh_port: free_port()?,
                    http_port: free_port()?,
                    extra: extra.clone(),
                    child: None,
                },
            );
        }
        Ok(Self {
            exe: exe.to_path_buf(),
            namespace: namespace.to_owned(),
            members,
            observer_port: free_port()?,
            mtls: None,
        })
    }

    /// Every link on mTLS with the access-control list: each service runs with
    /// `zenoh_dir/<service>.json5` (from `deploy/zenoh/mtls.sh`) and `tls/` endpoints; the
    /// observer holds the dashboard's certificate.
    pub fn with_mtls(mut self, zenoh_dir: &Path) -> Self {
        self.mtls = Some(zenoh_dir.to_path_buf());
        self
    }

    fn endpoint(&self, port: u16) -> String {
        let scheme = if self.mtls.is_some() { "tls" } else { "tcp" };
        format!("{scheme}/127.0.0.1:{port}")
    }

    /// Every endpoint except `port`'s.
    fn others(&self, port: u16) -> String {
        self.members
            .values()
            .map(|m| m.zenoh_port)
            .chain([self.observer_port])
            .filter(|p| *p != port)
            .map(|p| self.endpoint(p))
            .collect::<Vec<_>>()
            .join(",")
    }

    /// Starts `name`.
    pub fn spawn(&mut self, name: &str) -> anyhow::Result<()> {
        let member = self
            .members
            .get(name)
            .with_context(|| format!("no service {name}"))?;
        let mut command = Command::new(&self.exe);
        command
            .arg(name)
            .arg("--zenoh-listen")
            .arg(self.endpoint(member.zenoh_port))
            .arg("--zenoh-connect")
            .arg(self.others(member.zenoh_port))
            .arg("--http-addr")
            .arg(format!("127.0.0.1:{}", member.http_port))
            .arg("--namespace")
            .arg(&self.namespace)
            .args(&member.extra)
            .args(
                self.mtls
                    .iter()
                    .flat_map(|dir| ["--zenoh-config".into(), dir.join(format!("{name}.json5"))]),
            )
            .stdin(Stdio::null())
            .stdout(Stdio::null());
        if std::env::var_os("CONESIGHT_E2E_LOGS").is_none() {
            // Warnings and errors into a file, so a service that does not come up says why.
            let log = std::fs::File::create(self.log_path(name))
                .with_context(|| format!("creating {}", self.log_path(name).display()))?;
            command.stderr(log).env("RUST_LOG", "warn");
        }
        let child = command
            .spawn()
            .with_context(|| format!("spawning {name}"))?;
        if let Some(member) = self.members.get_mut(name) {
            member.child = Some(child);
        }
        Ok(())
    }

    /// Starts an [`Observer`] of `camera`'s cones, then every service, and waits (60 s at
    /// most: a service starts in under a second, but once took over 30 s on a 2-core machine
    /// under a parallel build) until each answers `/livez`.
    pub async fn start_observed(&mut self, camera: &str) -> anyhow::Result<Observer> {
        let observer = Observer::start(&self.observer_args(), camera).await?;
        self.spawn_all()?;
        self.wait_live(Duration::from_secs(60))?;
        Ok(observer)
    }

    /// Replaces the extra arguments `name` gets at its next start.
    pub fn set_args(&mut self, name: &str, extra: Vec<String>) {
        if let Some(member) = self.members.get_mut(name) {
            member.extra = extra;
        }
    }

    /// Starts every service.
    pub fn spawn_all(&mut self) -> anyhow::Result<()> {
        let names: Vec<String> = self.members.keys().cloned().collect();
        for name in names {
            self.spawn(&name)?;
        }
        Ok(())
    }

    /// Kills `name` (SIGKILL) and reaps it.
    pub fn kill(&mut self, name: &str) -> anyhow::Result<()> {
        if let Some(mut child) = self.members.get_mut(name).and_then(|m| m.child.take()) {
            child.kill()?;
            child.wait()?;
        }
        Ok(())
    }

    /// Freezes `name` (SIGSTOP) without ending it: a paused camera publishes nothing, so the
    /// benchmark can run its in-process blocks between bus blocks on a quiet bus. `resume`
    /// undoes it. Uses the `kill` command (procps or util-linux; the crate allows no unsafe
    /// code for a direct `kill(2)`).
    pub fn pause(&self, name: &str) -> anyhow::Result<()> {
        self.signal(name, "-STOP")
    }

    /// Lets a [`Cluster::pause`]d `name` go on (SIGCONT).
    pub fn resume(&self, name: &str) -> anyhow::Result<()> {
        self.signal(name, "-CONT")
    }

    fn signal(&self, name: &str, signal: &str) -> anyhow::Result<()> {
        let pid = self
            .pid(name)
            .with_context(|| format!("{name} is not running"))?;
        let status = Command::new("kill")
            .arg(signal)
            .arg(pid.to_string())
            .status()
            .with_context(|| {
                format!("running `kill {signal} {pid}` for {name} (install procps)")
            })?;
        anyhow::ensure!(
            status.success(),
            "`kill {signal} {pid}` for {name}: {status}"
        );
        Ok(())
    }

    /// Process id of `name`, while running.
    pub fn pid(&self, name: &str) -> Option<u32> {
        self.members.get(name)?.child.as_ref().map(Child::id)
    }

    /// True when `name` runs (has not exited).
    pub fn is_running(&mut self, name: &str) -> bool {
        self.members
            .get_mut(name)
            .and_then(|m| m.child.as_mut())
            .is_some_and(|child| matches!(child.try_wait(), Ok(None)))
    }

    /// Resident memory of `name`, KiB (Linux `/proc`).
    pub fn rss_kib(&self, name: &str) -> Option<u64> {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.pid(name)?)).ok()?;
        status
            .lines()
            .find_map(|l| l.strip_prefix("VmRSS:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
    }

    /// `GET path` on `name`'s HTTP server: (status, body).
    pub fn http(&self, name: &str, path: &str) -> anyhow::Result<(u16, String)> {
        let member = self
            .members
            .get(name)
            .with_context(|| format!("no service {name}"))?;
        http_get(member.http_port, path)
    }

    /// A metric's value on `name`'s `/metrics` (the line starting with `series`, e.g.
    /// `conesight_errors_total{kind="oversize"}`); 0 when absent.
    pub fn metric(&self, name: &str, series: &str) -> f64 {
        self.http(name, "/metrics")
            .ok()
            .and_then(|(_, body)| conesight_service::metrics::series_value(&body, series))
            .unwrap_or(0.0)
    }

    /// Where `name`'s warnings and errors go (unless `CONESIGHT_E2E_LOGS` is set).
    pub fn log_path(&self, name: &str) -> PathBuf {
        std::env::temp_dir().join(format!("conesight-e2e-{}-{name}.log", self.namespace))
    }

    /// Waits until every started service answers `/livez`; a service that exited or did not
    /// answer in time is an error with its exit status and the end of its log.
    pub fn wait_live(&mut self, timeout: Duration) -> anyhow::Result<()> {
        let deadline = Instant::now() + timeout;
        let names: Vec<String> = self
            .members
            .iter()
            .filter(|(_, m)| m.child.is_some())
            .map(|(name, _)| name.clone())
            .collect();
        for name in names {
            loop {
                if matches!(self.http(&name, "/livez"), Ok((200, _))) {
                    break;
                }
                let exited = self
                    .members
                    .get_mut(&name)
                    .and_then(|m| m.child.as_mut())
                    .and_then(|child| child.try_wait().ok().flatten());
                if exited.is_some() || Instant::now() >= deadline {
                    let log = std::fs::read_to_string(self.log_path(&name)).unwrap_or_default();
                    let tail: String = log
                        .lines()
                        .rev()
                        .take(20)
                        .collect::<Vec<_>>()
                        .into_iter()
                        .rev()
                        .collect::<Vec<_>>()
                        .join("\n");
                    anyhow::bail!(
                        "{name} did not come up within {timeout:?} (exit status: {exited:?}, http \
                         port {}); its log:\n{tail}",
                        self.members.get(&name).map_or(0, |m| m.http_port)
                    );
                }
                std::thread::sleep(Duration::from_millis(50));
            }
        }
        Ok(())
    }

    /// Zenoh args of an observer session joining the cluster.
    pub fn observer_args(&self) -> ZenohArgs {
        ZenohArgs {
            listen: vec![self.endpoint(self.observer_port)],
            connect: self
                .members
                .values()
                .map(|m| self.endpoint(m.zenoh_port))
                .collect(),
            config: self.mtls.as_ref().map(|dir| dir.join("dashboard.json5")),
            namespace: self.namespace.clone(),
            ..ZenohArgs::default()
        }
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        for member in self.members.values_mut() {
            if let Some(mut child) = member.child.take() {
                let _ = child.kill();
                let _ = child.wait();
            }
        }
    }
}

/// `GET path` on 127.0.0.1:`port`: (status, body).
pub fn http_get(port: u16, path: &str) -> anyhow::Result<(u16, String)> {
    let mut stream = TcpStream::connect(("127.0.0.1", port))?;
    stream.set_read_timeout(Some(Duration::from_secs(5)))?;
    write!(
        stream,
        "GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n"
    )?;
    let mut response = String::new();
    stream.read_to_string(&mut response)?;
    let status = response
        .get(9..12)
        .and_then(|s| s.parse().ok())
        .context("not an HTTP response")?;
    let body = response
        .split_once("\r\n\r\n")
        .map(|(_, b)| b.to_owned())
        .unwrap_or_default();
    Ok((status, body))
}

/// Certificates (`deploy/certs.sh`) and per-node mTLS configs (`deploy/zenoh/mtls.sh`) in a
/// fresh directory under the temp dir; the configs' directory, or `None` without `openssl`.
pub fn mtls_configs(name: &str) -> anyhow::Result<Option<PathBuf>> {
    if Command::new("openssl").arg("version").output().is_err() {
        return Ok(None);
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let dir =
        std::env::temp_dir().join(format!("conesight-e2e-mtls-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    for (script, args) in [
        ("deploy/certs.sh", vec![dir.join("certs")]),
        (
            "deploy/zenoh/mtls.sh",
            vec![dir.join("certs"), dir.join("zenoh")],
        ),
    ] {
        let output = Command::new(root.join(script)).args(&args).output()?;
        anyhow::ensure!(output.status.success(), "{script}: {output:?}");
    }
    Ok(Some(dir.join("zenoh")))
}

/// One `Cones` message as received.
#[derive(Debug, Clone)]
pub struct Received {
    /// Frame sequence.
    pub sequence: u64,
    /// Acquisition time, ns since the epoch.
    pub acquisition_ns: u64,
    /// Latency from acquisition to reception here, seconds.
    pub latency_secs: f64,
    /// When it arrived (test clock).
    pub at: Instant,
    /// The cones.
    pub cones: Vec<LocatedCone>,
}

/// An observer session collecting every `Cones` message of one camera.
#[derive(Debug)]
pub struct Observer {
    /// Everything received so far.
    pub received: Arc<Mutex<Vec<Received>>>,
    /// The session (kept open).
    pub session: conesight_bus::zenoh::Session,
}

impl Observer {
    /// Joins with `args` and collects `camera`'s cones in the background.
    pub async fn start(args: &ZenohArgs, camera: &str) -> anyhow::Result<Self> {
        let session = open_session(args).await?;
        let topics = Topics::from_args(args)?;
        let subscriber =
            declare_subscriber(&session, topics.key(camera, Stream::Cones)?, Stream::Cones).await?;
        let received = Arc::new(Mutex::new(Vec::new()));
        let sink = received.clone();
        tokio::spawn(async move {
            while let Ok(sample) = subscriber.recv_async().await {
                let Ok(message) = decode::<pb::Cones>(sample.payload()) else {
                    continue;
                };
                let Some(header) = message.header.clone() else {
                    continue;
                };
                let cones = message.to_core().unwrap_or_default();
                if let Ok(mut sink) = sink.lock() {
                    sink.push(Received {
                        sequence: header.frame_sequence,
                        acquisition_ns: header.acquisition_time_ns,
                        latency_secs: now_ns().saturating_sub(header.acquisition_time_ns) as f64
                            / 1e9,
                        at: Instant::now(),
                        cones,
                    });
                }
            }
        });
        Ok(Self { received, session })
    }

    /// A copy of everything received.
    pub fn snapshot(&self) -> Vec<Received> {
        self.received.lock().map(|r| r.clone()).unwrap_or_default()
    }

    /// Number of messages received.
    pub fn count(&self) -> usize {
        self.received.lock().map(|r| r.len()).unwrap_or(0)
    }

    /// Waits until `predicate` holds on the messages received, or `timeout`; returns whether
    /// it held.
    pub async fn wait_for(
        &self,
        timeout: Duration,
        predicate: impl Fn(&[Received]) -> bool,
    ) -> bool {
        let deadline = Instant::now() + timeout;
        loop {
            let held = self.received.lock().map(|r| predicate(&r)).unwrap_or(false);
            if held {
                return true;
            }
            if Instant::now() >= deadline {
                return false;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }
}

/// One message of a stream as seen by a [`StreamLog`].
#[derive(Debug, Clone, Copy)]
pub struct Stamp {
    /// Frame sequence.
    pub sequence: u64,
    /// Acquisition time of the frame, ns.
    pub acquisition_ns: u64,
    /// Publish time of the message, ns.
    pub publish_ns: u64,
    /// When it arrived here, ns.
    pub received_ns: u64,
}

/// Headers of every message of one stream of one camera, collected in the background.
#[derive(Debug, Clone, Default)]
pub struct StreamLog {
    /// Everything received so far.
    pub stamps: Arc<Mutex<Vec<Stamp>>>,
    /// The subscriber filling `stamps` (undeclared with the last clone).
    _subscriber: Option<Arc<conesight_bus::zenoh::pubsub::Subscriber<()>>>,
}

impl StreamLog {
    /// Collects `stream` of `camera` on `session`. Receipt is stamped in the subscriber's
    /// callback, on Zenoh's receive thread: when the bus delivers the message, not when some
    /// task of this process gets round to it.
    pub async fn start(
        session: &conesight_bus::zenoh::Session,
        topics: &Topics,
        camera: &str,
        stream: Stream,
    ) -> anyhow::Result<Self> {
        let stamps: Arc<Mutex<Vec<Stamp>>> = Arc::default();
        let sink = stamps.clone();
        let subscriber = conesight_bus::declare_callback_subscriber(
            session,
            topics.key(camera, stream)?,
            move |sample| {
                let received_ns = now_ns();
                let Ok(header) =
                    conesight_proto::peek_header(conesight_bus::payload_buf(sample.payload()))
                else {
                    return;
                };
                if let Ok(mut sink) = sink.lock() {
                    sink.push(Stamp {
                        sequence: header.frame_sequence,
                        acquisition_ns: header.acquisition_time_ns,
                        publish_ns: header.publish_time_ns,
                        received_ns,
                    });
                }
            },
        )
        .await?;
        Ok(Self {
            stamps,
            _subscriber: Some(Arc::new(subscriber)),
        })
    }

    /// The sequence of every message received so far, in arrival order.
    pub fn sequences(&self) -> Vec<u64> {
        self.stamps
            .lock()
            .map(|s| s.iter().map(|t| t.sequence).collect())
            .unwrap_or_default()
    }

    /// Stamps received between `from_ns` and `to_ns`, keyed by (sequence, acquisition).
    pub fn between(&self, from_ns: u64, to_ns: u64) -> BTreeMap<(u64, u64), Stamp> {
        self.stamps
            .lock()
            .map(|s| {
                s.iter()
                    .filter(|t| (from_ns..to_ns).contains(&t.received_ns))
                    .map(|t| ((t.sequence, t.acquisition_ns), *t))
                    .collect()
            })
            .unwrap_or_default()
    }
}

/// Whether this process may lock `bytes` of memory, as Zenoh's shared memory does for its
/// pool (`mlock`): the `Max locked memory` limit allows it or the process has CAP_IPC_LOCK
/// (root in most sandboxes; not in a default Docker container).
pub fn memory_lockable(bytes: u64) -> bool {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let cap_ipc_lock = status
        .lines()
        .find_map(|l| l.strip_prefix("CapEff:"))
        .and_then(|hex| u64::from_str_radix(hex.trim(), 16).ok())
        .is_some_and(|caps| caps & (1 << 14) != 0);
    let limits = std::fs::read_to_string("/proc/self/limits").unwrap_or_default();
    let limit_ok = limits
        .lines()
        .find(|l| l.starts_with("Max locked memory"))
        .and_then(|l| l.split_whitespace().nth(3))
        .is_some_and(|soft| soft == "unlimited" || soft.parse::<u64>().is_ok_and(|b| b >= bytes));
    cap_ipc_lock || limit_ok
}

/// Publishers on every input stream of one camera, for a test that plays a peer feeding the
/// services by hand.
pub struct Inputs {
    /// `frame`.
    pub frames: conesight_bus::zenoh::pubsub::Publisher<'static>,
    /// `detections`.
    pub detections: conesight_bus::zenoh::pubsub::Publisher<'static>,
    /// `keypoints`.
    pub keypoints: conesight_bus::zenoh::pubsub::Publisher<'static>,
    /// `camera_info`.
    pub camera_info: conesight_bus::zenoh::pubsub::Publisher<'static>,
}

impl Inputs {
    /// Declares the four publishers on `session` in `namespace` (vehicle `car`), then waits
    /// 2 s for the declarations to reach the services.
    pub async fn declare(
        session: &conesight_bus::zenoh::Session,
        namespace: &str,
        camera: &str,
    ) -> anyhow::Result<Self> {
        use conesight_bus::declare_publisher;
        let topics = Topics::new(namespace, "car")?;
        let inputs = Self {
            frames: declare_publisher(session, &topics, camera, Stream::Frame).await?,
            detections: declare_publisher(session, &topics, camera, Stream::Detections).await?,
            keypoints: declare_publisher(session, &topics, camera, Stream::Keypoints).await?,
            camera_info: declare_publisher(session, &topics, camera, Stream::CameraInfo).await?,
        };
        tokio::time::sleep(Duration::from_secs(2)).await;
        Ok(inputs)
    }
}

/// Seven keypoints spread over a cone's box (apex, stripe edges, bases), enough for a pose: for
/// tests that play the keypoints service by hand.
pub fn keypoints_in(b: &conesight_vision::PixelBox) -> [nalgebra::Point2<f64>; 7] {
    let (w, h) = (b.x_max_px - b.x_min_px, b.y_max_px - b.y_min_px);
    let cx = 0.5 * (b.x_min_px + b.x_max_px);
    let at = |dx: f64, fy: f64| nalgebra::Point2::new(cx + dx * w, b.y_min_px + fy * h);
    [
        at(0.0, 0.0),
        at(-0.2, 0.35),
        at(-0.33, 0.65),
        at(-0.5, 1.0),
        at(0.2, 0.35),
        at(0.33, 0.65),
        at(0.5, 1.0),
    ]
}
