//! Opening the Zenoh session from [`ZenohArgs`].

use zenoh::{Config, Session};

use crate::args::{ZenohArgs, ZenohMode};
use crate::error::BusError;
use crate::security::check_enforceable;
use crate::topics::Topics;

/// Shared-memory pool of a session without a config file, MiB: nine raw 1920x1200 RGB8 frames
/// (6.9 MB each), so frames still held by subscribers (the detector's slot, the keypoint
/// service's pairing cache) leave room for new ones. Zenoh's own default, 16 MiB, holds two.
pub const DEFAULT_SHM_POOL_MB: usize = 64;

/// The Zenoh config of `args`: the config file (or Zenoh's defaults), then the flags given on
/// top: mode (peer without a file), endpoints, multicast scouting (off without a file) and
/// shared memory (Zenoh's default, on, unless turned off) with a pool of `--zenoh-shm-pool-mb`
/// ([`DEFAULT_SHM_POOL_MB`] without a file). Auth or access-control settings this build cannot
/// enforce are refused ([`check_enforceable`], [`BusError::Unenforceable`]).
pub fn zenoh_config(args: &ZenohArgs) -> Result<Config, BusError> {
    let mut config = match &args.config {
        Some(path) => Config::from_file(path).map_err(|source| BusError::ConfigFile {
            path: path.clone(),
            source,
        })?,
        None => Config::default(),
    };
    match (args.mode, &args.config) {
        (Some(mode), _) => set(&mut config, "mode", json_string(mode.as_str()))?,
        (None, None) => set(&mut config, "mode", json_string(ZenohMode::Peer.as_str()))?,
        (None, Some(_)) => {}
    }
    if !args.connect.is_empty() {
        set(&mut config, "connect/endpoints", json_list(&args.connect))?;
    }
    if !args.listen.is_empty() {
        set(&mut config, "listen/endpoints", json_list(&args.listen))?;
    }
    match (args.multicast_scouting, &args.config) {
        (Some(enabled), _) => set(
            &mut config,
            "scouting/multicast/enabled",
            enabled.to_string(),
        )?,
        (None, None) => set(
            &mut config,
            "scouting/multicast/enabled",
            "false".to_owned(),
        )?,
        (None, Some(_)) => {}
    }
    if let Some(enabled) = args.shared_memory {
        set(
            &mut config,
            "transport/shared_memory/enabled",
            enabled.to_string(),
        )?;
    }
    let pool_mb = match (args.shm_pool_mb, &args.config) {
        (Some(pool_mb), _) => Some(pool_mb),
        (None, None) => Some(DEFAULT_SHM_POOL_MB),
        (None, Some(_)) => None,
    };
    if let Some(pool_mb) = pool_mb {
        set(
            &mut config,
            "transport/shared_memory/transport_optimization/pool_size",
            pool_mb.max(1).saturating_mul(1 << 20).to_string(),
        )?;
    }
    if let Some(bytes) = args.rx_max_message_bytes {
        set(
            &mut config,
            "transport/link/rx/max_message_size",
            bytes.max(1 << 16).to_string(),
        )?;
    }
    check_enforceable(&config)?;
    Ok(config)
}

/// Size of the shared-memory pool a session of `args` gets, bytes (the config file's or the
/// flags' `transport/shared_memory/transport_optimization/pool_size`); `None` when it cannot be
/// read.
pub fn shm_pool_bytes(args: &ZenohArgs) -> Option<usize> {
    let config = zenoh_config(args).ok()?;
    config
        .get_json("transport/shared_memory/transport_optimization/pool_size")
        .ok()?
        .trim_matches('"')
        .parse()
        .ok()
}

/// Opens the session described by `args`.
pub async fn open_session(args: &ZenohArgs) -> Result<Session, BusError> {
    let config = zenoh_config(args)?;
    let session = zenoh::open(config)
        .await
        .map_err(|source| BusError::Open { source })?;
    tracing::info!(
        zid = %session.zid(),
        mode = ?args.mode,
        connect = ?args.connect,
        listen = ?args.listen,
        "zenoh session open"
    );
    Ok(session)
}

fn set(config: &mut Config, key: &'static str, value: String) -> Result<(), BusError> {
    config
        .insert_json5(key, &value)
        .map_err(|source| BusError::ConfigValue { key, value, source })
}

fn json_string(value: &str) -> String {
    serde_json::Value::String(value.to_owned()).to_string()
}

fn json_list(values: &[String]) -> String {
    serde_json::Value::from(values.to_vec()).to_string()
}

/// A TCP port free on 127.0.0.1 for a process (or session) about to listen on it, for tests
/// and scripts that start services on fixed endpoints. Taken below Linux's ephemeral range
/// (32768-60999): a port the kernel hands out for `:0` comes from that range, where any
/// outgoing connection (Zenoh peers dialling each other) may take it before the service binds
/// it, which made services of the end-to-end tests fail with "address already in use". Each
/// call in a process gives another port (a counter from an offset of the process id), checked
/// free by binding it.
pub fn free_loopback_port() -> std::io::Result<u16> {
    use std::sync::atomic::{AtomicU32, Ordering};
    const FIRST: u32 = 20_000;
    const COUNT: u32 = 12_000;
    static NEXT: AtomicU32 = AtomicU32::new(u32::MAX);
    let _ = NEXT.compare_exchange(
        u32::MAX,
        (std::process::id().wrapping_mul(97)) % COUNT,
        Ordering::Relaxed,
        Ordering::Relaxed,
    );
    for _ in 0..COUNT {
        let offset = NEXT.fetch_add(1, Ordering::Relaxed) % COUNT;
        let port = u16::try_from(FIRST + offset).unwrap_or(u16::MAX);
        if std::net::TcpListener::bind(("127.0.0.1", port)).is_ok() {
            return Ok(port);
        }
    }
    Err(std::io::Error::new(
        std::io::ErrorKind::AddrInUse,
        "no free port in 20000-31999 on 127.0.0.1",
    ))
}

/// Two peer sessions on 127.0.0.1 in `namespace`, the second connected to the first (both
/// listen on loopback only), with the namespace's keys: for tests and examples that need a
/// real bus between two participants.
pub async fn loopback_pair(namespace: &str) -> Result<(Session, Session, Topics), BusError> {
    let port = free_loopback_port().map_err(|error| BusError::Open {
        source: error.into(),
    })?;
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let base = ZenohArgs {
        namespace: namespace.to_owned(),
        ..ZenohArgs::default()
    };
    let listener = open_session(&ZenohArgs {
        listen: vec![endpoint.clone()],
        ..base.clone()
    })
    .await?;
    let connector = open_session(&ZenohArgs {
        connect: vec![endpoint],
        // Listen on loopback only too (Zenoh's default peer listener binds every interface).
        listen: vec!["tcp/127.0.0.1:0".to_owned()],
        ..base.clone()
    })
    .await?;
    Ok((listener, connector, Topics::from_args(&base)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn get(config: &Config, key: &str) -> String {
        config.get_json(key).unwrap()
    }

    #[test]
    fn the_pool_size_is_read_back() {
        assert_eq!(
            shm_pool_bytes(&ZenohArgs::default()),
            Some(DEFAULT_SHM_POOL_MB << 20)
        );
        let args = ZenohArgs {
            shm_pool_mb: Some(9),
            ..ZenohArgs::default()
        };
        assert_eq!(shm_pool_bytes(&args), Some(9 << 20));
    }

    #[test]
    fn defaults_are_peer_without_multicast() {
        let config = zenoh_config(&ZenohArgs::default()).unwrap();
        assert_eq!(get(&config, "mode"), "\"peer\"");
        assert_eq!(get(&config, "scouting/multicast/enabled"), "false");
        assert_eq!(
            get(
                &config,
                "transport/shared_memory/transport_optimization/pool_size"
            ),
            (DEFAULT_SHM_POOL_MB << 20).to_string()
        );
    }

    #[test]
    fn flags_reach_the_config() {
        let args = ZenohArgs {
            mode: Some(ZenohMode::Client),
            connect: vec!["tcp/127.0.0.1:7447".into()],
            listen: vec!["tcp/127.0.0.1:0".into()],
            multicast_scouting: Some(true),
            shared_memory: Some(false),
            shm_pool_mb: Some(48),
            ..ZenohArgs::default()
        };
        let config = zenoh_config(&args).unwrap();
        assert_eq!(
            get(
                &config,
                "transport/shared_memory/transport_optimization/pool_size"
            ),
            (48 << 20).to_string()
        );
        assert_eq!(get(&config, "mode"), "\"client\"");
        assert!(get(&config, "connect/endpoints").contains("tcp/127.0.0.1:7447"));
        assert!(get(&config, "listen/endpoints").contains("tcp/127.0.0.1:0"));
        assert_eq!(get(&config, "scouting/multicast/enabled"), "true");
        assert_eq!(get(&config, "transport/shared_memory/enabled"), "false");
    }

    #[test]
    fn bad_endpoint_and_missing_file_are_errors() {
        let args = ZenohArgs {
            connect: vec!["not an endpoint".into()],
            ..ZenohArgs::default()
        };
        assert!(matches!(
            zenoh_config(&args),
            Err(BusError::ConfigValue {
                key: "connect/endpoints",
                ..
            })
        ));
        let args = ZenohArgs {
            config: Some("/nonexistent/zenoh.json5".into()),
            ..ZenohArgs::default()
        };
        let error = zenoh_config(&args).unwrap_err();
        assert!(
            error.to_string().contains("/nonexistent/zenoh.json5"),
            "{error}"
        );
    }

    #[test]
    fn config_file_is_read_and_flags_override_it() {
        let dir = std::env::temp_dir().join(format!("conesight-bus-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("zenoh.json5");
        std::fs::write(
            &path,
            r#"{ mode: "router", scouting: { multicast: { enabled: true } } }"#,
        )
        .unwrap();
        let args = ZenohArgs {
            config: Some(path.clone()),
            ..ZenohArgs::default()
        };
        let config = zenoh_config(&args).unwrap();
        // Without flags the file's values stay; a flag overrides the file.
        assert_eq!(get(&config, "scouting/multicast/enabled"), "true");
        assert_eq!(get(&config, "mode"), "\"router\"");
        let args = ZenohArgs {
            mode: Some(ZenohMode::Peer),
            multicast_scouting: Some(false),
            ..args
        };
        let config = zenoh_config(&args).unwrap();
        assert_eq!(get(&config, "scouting/multicast/enabled"), "false");
        assert_eq!(get(&config, "mode"), "\"peer\"");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
