//! [`ZenohArgs`]: the Zenoh and key arguments every service flattens into its clap args
//! (`#[command(flatten)] zenoh: ZenohArgs`), each with an environment fallback for containers.

use std::path::PathBuf;

/// How the session joins the network.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ZenohMode {
    /// Talk directly to the peers given by `--zenoh-connect` / reached through `--zenoh-listen`.
    Peer,
    /// Go through the router(s) given by `--zenoh-connect`.
    Client,
    /// Be a router (the compose file's bus).
    Router,
}

impl ZenohMode {
    /// Zenoh's name of the mode.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Peer => "peer",
            Self::Client => "client",
            Self::Router => "router",
        }
    }
}

/// How a camera publishes its frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum FrameEncoding {
    /// Raw RGB8: no codec cost; zero-copy over shared memory on one host.
    Raw,
    /// JPEG: for frames that cross hosts.
    Jpeg,
}

/// Zenoh session and key arguments shared by every service.
#[derive(Debug, Clone, PartialEq, clap::Args)]
pub struct ZenohArgs {
    /// Zenoh mode; peer unless the config file or this flag says otherwise.
    #[arg(long = "zenoh-mode", env = "CONESIGHT_ZENOH_MODE", value_enum)]
    pub mode: Option<ZenohMode>,
    /// Endpoints to connect to, comma separated (e.g. tcp/10.0.0.2:7447).
    #[arg(
        long = "zenoh-connect",
        env = "CONESIGHT_ZENOH_CONNECT",
        value_delimiter = ','
    )]
    pub connect: Vec<String>,
    /// Endpoints to listen on, comma separated (e.g. tcp/0.0.0.0:7447).
    #[arg(
        long = "zenoh-listen",
        env = "CONESIGHT_ZENOH_LISTEN",
        value_delimiter = ','
    )]
    pub listen: Vec<String>,
    /// A Zenoh config file (JSON5); the other Zenoh flags given override it.
    #[arg(long = "zenoh-config", env = "CONESIGHT_ZENOH_CONFIG")]
    pub config: Option<PathBuf>,
    /// Multicast scouting (UDP discovery); off unless the config file or this flag turns it on.
    #[arg(
        long = "zenoh-multicast-scouting",
        env = "CONESIGHT_ZENOH_MULTICAST_SCOUTING"
    )]
    pub multicast_scouting: Option<bool>,
    /// Shared memory between processes on one host; on unless the config file or this flag
    /// turns it off.
    #[arg(long = "zenoh-shm", env = "CONESIGHT_ZENOH_SHM")]
    pub shared_memory: Option<bool>,
    /// Size of the shared-memory pool frames are written into, MiB (default 64 without a config
    /// file: nine raw 1920x1200 frames; Zenoh's own default is 16 MiB, two frames; too small a
    /// pool makes large messages fall back to the socket). Zenoh locks the pool in memory.
    #[arg(long = "zenoh-shm-pool-mb", env = "CONESIGHT_ZENOH_SHM_POOL_MB")]
    pub shm_pool_mb: Option<usize>,
    /// Run namespace: `live` on the car, a fresh name per replay so runs never mix.
    #[arg(long, env = "CONESIGHT_NAMESPACE", default_value = "live")]
    pub namespace: String,
    /// Vehicle name in the keys.
    #[arg(long, env = "CONESIGHT_VEHICLE", default_value = "car")]
    pub vehicle: String,
    /// Encoding of published frames (raw on one host, jpeg across hosts).
    #[arg(long = "frame-encoding", env = "CONESIGHT_FRAME_ENCODING", value_enum, default_value_t = FrameEncoding::Raw)]
    pub frame_encoding: FrameEncoding,
    /// JPEG quality of published frames, 1..=100.
    #[arg(long = "jpeg-quality", env = "CONESIGHT_JPEG_QUALITY", default_value_t = 90,
          value_parser = clap::value_parser!(u8).range(1..=100))]
    pub jpeg_quality: u8,
    /// Largest message Zenoh itself reassembles, bytes (its `transport/link/rx/
    /// max_message_size`, 1 GiB by default): a larger one is refused fragment by fragment and
    /// never buffered whole. Not a flag: a service sets it from its `--max-message-mb`.
    #[arg(skip)]
    pub rx_max_message_bytes: Option<usize>,
}

impl Default for ZenohArgs {
    /// The defaults of the command line: peer, no endpoints, scouting off, shm on, `live/car`.
    fn default() -> Self {
        Self {
            mode: None,
            connect: Vec::new(),
            listen: Vec::new(),
            config: None,
            multicast_scouting: None,
            shared_memory: None,
            shm_pool_mb: None,
            namespace: "live".to_owned(),
            vehicle: "car".to_owned(),
            frame_encoding: FrameEncoding::Raw,
            jpeg_quality: 90,
            rx_max_message_bytes: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        zenoh: ZenohArgs,
    }

    #[test]
    fn defaults_match_default_impl() {
        let cli = Cli::try_parse_from(["svc"]).unwrap();
        // The environment of the test process may set CONESIGHT_* variables; only compare
        // when it does not.
        if std::env::vars().all(|(k, _)| !k.starts_with("CONESIGHT_")) {
            assert_eq!(cli.zenoh, ZenohArgs::default());
        }
    }

    #[test]
    fn flags_parse() {
        let cli = Cli::try_parse_from([
            "svc",
            "--zenoh-mode",
            "client",
            "--zenoh-connect",
            "tcp/127.0.0.1:7447,tcp/127.0.0.1:7448",
            "--zenoh-listen",
            "tcp/127.0.0.1:0",
            "--zenoh-multicast-scouting",
            "true",
            "--zenoh-shm",
            "false",
            "--zenoh-shm-pool-mb",
            "64",
            "--namespace",
            "replay7",
            "--frame-encoding",
            "jpeg",
            "--jpeg-quality",
            "75",
        ])
        .unwrap();
        let z = cli.zenoh;
        assert_eq!(z.mode, Some(ZenohMode::Client));
        assert_eq!(z.connect.len(), 2);
        assert_eq!(z.listen, ["tcp/127.0.0.1:0"]);
        assert_eq!(z.multicast_scouting, Some(true));
        assert_eq!(z.shared_memory, Some(false));
        assert_eq!(z.shm_pool_mb, Some(64));
        assert_eq!(z.namespace, "replay7");
        assert_eq!(z.frame_encoding, FrameEncoding::Jpeg);
        assert_eq!(z.jpeg_quality, 75);
        assert!(Cli::try_parse_from(["svc", "--jpeg-quality", "0"]).is_err());
        assert!(Cli::try_parse_from(["svc", "--zenoh-mode", "bridge"]).is_err());
    }
}
