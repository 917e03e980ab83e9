//! Helpers shared by the tests that run `conesight` as processes on loopback.
#![allow(dead_code, clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

pub const BIN: &str = env!("CARGO_BIN_EXE_conesight");

/// A fresh folder under the system temp dir, removed on drop.
pub struct TempDir(pub PathBuf);

impl TempDir {
    pub fn new(name: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("conesight-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Self(dir)
    }

    pub fn join(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A free TCP port on 127.0.0.1, outside the ephemeral range (`conesight_bus::free_loopback_port`).
pub fn free_port() -> u16 {
    conesight_bus::free_loopback_port().unwrap()
}

/// A child process killed (SIGKILL) on drop unless it was waited for.
pub struct Process {
    pub child: Child,
    pub name: String,
    pub log: PathBuf,
}

impl Process {
    /// `conesight ARGS`, stdout and stderr into `log` (`.out` beside it for stdout).
    pub fn start(name: &str, args: &[&str], log: &Path) -> Self {
        Self::start_program(name, BIN, args, log)
    }

    /// `program ARGS`, as [`Process::start`].
    pub fn start_program(name: &str, program: &str, args: &[&str], log: &Path) -> Self {
        let stderr = std::fs::File::create(log).unwrap();
        let stdout = std::fs::File::create(log.with_extension("out")).unwrap();
        let child = Command::new(program)
            .args(args)
            .stdin(Stdio::null())
            .stdout(stdout)
            .stderr(stderr)
            .spawn()
            .unwrap();
        Self {
            child,
            name: name.to_owned(),
            log: log.to_path_buf(),
        }
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// SIGINT (Ctrl-C), then waits at most `limit`; the exit status.
    pub fn interrupt(&mut self, limit: Duration) -> std::process::ExitStatus {
        let status = Command::new("kill")
            .args(["-INT", &self.pid().to_string()])
            .status()
            .unwrap();
        assert!(status.success());
        self.wait(limit)
    }

    /// Waits at most `limit` for the process to end.
    pub fn wait(&mut self, limit: Duration) -> std::process::ExitStatus {
        let started = Instant::now();
        loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                return status;
            }
            assert!(
                started.elapsed() < limit,
                "{} did not end within {limit:?}; log:\n{}",
                self.name,
                self.log_text()
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    pub fn log_text(&self) -> String {
        format!(
            "{}\n--- stdout ---\n{}",
            std::fs::read_to_string(&self.log).unwrap_or_default(),
            self.stdout()
        )
    }

    pub fn stdout(&self) -> String {
        std::fs::read_to_string(self.log.with_extension("out")).unwrap_or_default()
    }
}

impl Drop for Process {
    fn drop(&mut self) {
        if matches!(self.child.try_wait(), Ok(None)) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// How many distinct frames [`start_looped_run`]'s drive loops over: frames `n` and
/// `n + LOOP_FRAMES` are the same image, so they give the same cones.
pub const LOOP_FRAMES: u64 = 10;
const LOOP_FRAMES_STR: &str = "10";

/// `conesight run` of the whole pipeline on a looped 10-frame synthetic drive at 5 Hz until
/// killed, in a namespace of its own, with `extra` flags (e.g. `--dashboard-addr ADDR`); its out
/// folder and logs in `dir`. Returns the process, its Zenoh endpoint and its namespace.
pub fn start_looped_run(dir: &TempDir, name: &str, extra: &[&str]) -> (Process, String, String) {
    let namespace = format!("{name}{}", std::process::id());
    let listen = format!("tcp/127.0.0.1:{}", free_port());
    let out = dir.join("out");
    let log = dir.join("run.log");
    let mut args = vec![
        "run",
        "--frames",
        "0",
        "--rate-hz",
        "5",
        "--preload",
        LOOP_FRAMES_STR,
        "--namespace",
        &namespace,
        "--zenoh-listen",
        &listen,
        "--out",
        out.to_str().unwrap(),
        "--log-file",
        log.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let process = Process::start("run", &args, &dir.join("run.stderr"));
    (process, listen, namespace)
}

/// The body of `GET path` on 127.0.0.1:`port` (`None` when nothing answers).
pub fn http_get(port: u16, path: &str) -> Option<String> {
    let mut stream = TcpStream::connect(("127.0.0.1", port)).ok()?;
    stream.set_read_timeout(Some(Duration::from_secs(5))).ok()?;
    write!(
        stream,
        "GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n"
    )
    .ok()?;
    let mut response = String::new();
    stream.read_to_string(&mut response).ok()?;
    response
        .split_once("\r\n\r\n")
        .map(|(_, body)| body.to_owned())
}

/// The value of the series `name` (labels it names must be there; others, such as `service`
/// and `camera`, may be too) in a Prometheus text body.
pub fn metric(body: &str, name: &str) -> Option<f64> {
    conesight_service::metrics::series_value(body, name)
}

/// Resident memory of process `pid`, bytes (VmRSS of /proc/PID/status).
pub fn rss_bytes(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}
