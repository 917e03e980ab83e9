//! [`healthcheck()`]: `GET /readyz` over plain HTTP/1.1, for container health checks in images
//! without curl (`my-service healthcheck`).

use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr};
use std::process::ExitCode;
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

/// Most response bytes read.
const MAX_RESPONSE_BYTES: u64 = 64 * 1024;

/// Arguments of a `healthcheck` subcommand.
#[derive(Debug, Clone, PartialEq, clap::Args)]
pub struct HealthcheckArgs {
    /// The service's HTTP address; an unspecified IP (0.0.0.0, ::) means this host.
    #[arg(
        long = "http-addr",
        env = "CONESIGHT_HTTP_ADDR",
        default_value = "127.0.0.1:9090"
    )]
    pub addr: SocketAddr,
    /// Path to probe.
    #[arg(long, default_value = "/readyz")]
    pub path: String,
    /// Give up after this many seconds.
    #[arg(long = "timeout-secs", default_value_t = 2.0)]
    pub timeout_secs: f64,
}

impl HealthcheckArgs {
    /// Runs the check: exit code 0 when healthy, 1 (with the reason on stderr) otherwise.
    pub async fn run(&self) -> ExitCode {
        match healthcheck(self).await {
            Ok(()) => ExitCode::SUCCESS,
            Err(error) => {
                eprintln!("unhealthy: {error}");
                ExitCode::FAILURE
            }
        }
    }
}

/// Why a health check failed.
#[derive(Debug, thiserror::Error)]
pub enum HealthcheckError {
    /// No answer in time.
    #[error("no answer from {addr} within {timeout:?}")]
    Timeout {
        /// The address probed.
        addr: SocketAddr,
        /// The time allowed.
        timeout: Duration,
    },
    /// Connecting, writing or reading failed.
    #[error("cannot query {addr}: {source}")]
    Io {
        /// The address probed.
        addr: SocketAddr,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The answer is not HTTP.
    #[error("{addr} answered something that is not HTTP: {status_line:?}")]
    NotHttp {
        /// The address probed.
        addr: SocketAddr,
        /// The first line received.
        status_line: String,
    },
    /// The service answered with a non-2xx status.
    #[error("{path} answered {status}: {body}")]
    Unhealthy {
        /// The path probed.
        path: String,
        /// HTTP status code.
        status: u16,
        /// Response body (the readiness conditions).
        body: String,
    },
}

/// Probes `args.path` on `args.addr`; `Ok` on a 2xx answer.
pub async fn healthcheck(args: &HealthcheckArgs) -> Result<(), HealthcheckError> {
    let addr = local_if_unspecified(args.addr);
    let timeout = Duration::from_secs_f64(args.timeout_secs.clamp(0.001, 3600.0));
    let response = tokio::time::timeout(timeout, get(addr, &args.path))
        .await
        .map_err(|_| HealthcheckError::Timeout { addr, timeout })?
        .map_err(|source| HealthcheckError::Io { addr, source })?;
    let (head, body) = response.split_once("\r\n\r\n").unwrap_or((&response, ""));
    let status_line = head.lines().next().unwrap_or_default();
    let status = status_line
        .strip_prefix("HTTP/1.")
        .and_then(|rest| rest.get(2..5))
        .and_then(|code| code.parse::<u16>().ok())
        .ok_or_else(|| HealthcheckError::NotHttp {
            addr,
            status_line: status_line.chars().take(80).collect(),
        })?;
    if (200..300).contains(&status) {
        Ok(())
    } else {
        Err(HealthcheckError::Unhealthy {
            path: args.path.clone(),
            status,
            body: body.trim().replace('\n', ", "),
        })
    }
}

fn local_if_unspecified(addr: SocketAddr) -> SocketAddr {
    match addr.ip() {
        IpAddr::V4(ip) if ip.is_unspecified() => (Ipv4Addr::LOCALHOST, addr.port()).into(),
        IpAddr::V6(ip) if ip.is_unspecified() => (Ipv6Addr::LOCALHOST, addr.port()).into(),
        _ => addr,
    }
}

async fn get(addr: SocketAddr, path: &str) -> std::io::Result<String> {
    let mut stream = TcpStream::connect(addr).await?;
    let request = format!("GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n");
    stream.write_all(request.as_bytes()).await?;
    let mut response = Vec::new();
    stream
        .take(MAX_RESPONSE_BYTES)
        .read_to_end(&mut response)
        .await?;
    Ok(String::from_utf8_lossy(&response).into_owned())
}
