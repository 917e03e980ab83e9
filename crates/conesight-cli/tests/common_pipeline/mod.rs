//! The four services as four `conesight run --services X` processes on loopback Zenoh, each
//! listening on its own port and connecting to the others: what a dashboard, `conesight
//! status` and a restarted service see of a split pipeline.
#![allow(dead_code, clippy::unwrap_used, clippy::expect_used, missing_docs)]

use conesight_bus::ZenohArgs;

use crate::common_process::{Process, TempDir, free_port, http_get, metric};

pub const SERVICES: [&str; 4] = ["camera", "detector", "keypoints", "localiser"];

pub struct Pipeline {
    pub namespace: String,
    pub endpoints: Vec<String>,
    pub http_base: u16,
    pub processes: Vec<Option<Process>>,
    /// Each service's arguments, to start it again.
    args: Vec<Vec<String>>,
    /// Where each service's log goes (a restart gets a new one).
    dir: std::path::PathBuf,
    starts: usize,
}

impl Pipeline {
    /// The four services of namespace `name` + this test process's id; `camera_args` go to the
    /// camera (none: its defaults, 10 Hz and 20 frames rendered up front).
    pub fn start(dir: &TempDir, name: &str, camera_args: &[&str]) -> Self {
        let namespace = format!("{name}{}", std::process::id());
        let endpoints: Vec<String> = (0..5)
            .map(|_| format!("tcp/127.0.0.1:{}", free_port()))
            .collect();
        let http_base = free_port().saturating_sub(10).max(20_000);
        let base = http_base.to_string();
        let mut all_args = Vec::new();
        for (index, service) in SERVICES.iter().enumerate() {
            let others: Vec<&str> = endpoints
                .iter()
                .enumerate()
                .filter(|(i, _)| *i != index)
                .map(|(_, e)| e.as_str())
                .collect();
            let others = others.join(",");
            let out = dir.join(service);
            let mut args: Vec<String> = [
                "run",
                "--services",
                service,
                "--namespace",
                &namespace,
                "--zenoh-listen",
                &endpoints[index],
                "--zenoh-connect",
                &others,
                "--frames",
                "0",
                "--http-base-port",
                &base,
                "--out",
                out.to_str().unwrap(),
            ]
            .iter()
            .map(|s| (*s).to_owned())
            .collect();
            if *service == "camera" {
                args.extend(camera_args.iter().map(|s| (*s).to_owned()));
            }
            all_args.push(args);
        }
        let mut pipeline = Self {
            namespace,
            endpoints,
            http_base,
            processes: Vec::new(),
            args: all_args,
            dir: dir.join(""),
            starts: 0,
        };
        for service in SERVICES {
            let process = pipeline.spawn(service);
            pipeline.processes.push(Some(process));
        }
        pipeline
    }

    fn index(service: &str) -> usize {
        SERVICES.iter().position(|s| *s == service).unwrap()
    }

    fn spawn(&mut self, service: &str) -> Process {
        self.starts += 1;
        let args: Vec<&str> = self.args[Self::index(service)]
            .iter()
            .map(String::as_str)
            .collect();
        Process::start(
            service,
            &args,
            &self.dir.join(format!("{service}-{}.log", self.starts)),
        )
    }

    /// Kills `service` with SIGKILL (kill -9) and reaps it.
    pub fn kill(&mut self, service: &str) {
        if let Some(mut process) = self.processes[Self::index(service)].take() {
            process.child.kill().unwrap();
            process.child.wait().unwrap();
        }
    }

    /// Starts `service` again with the arguments it had.
    pub fn restart(&mut self, service: &str) {
        let process = self.spawn(service);
        self.processes[Self::index(service)] = Some(process);
    }

    /// The HTTP port of `service` (`--http-base-port` + its index).
    pub fn http_port(&self, service: &str) -> u16 {
        self.http_base + u16::try_from(Self::index(service)).unwrap()
    }

    /// `name` in `service`'s /metrics (`None` while it does not answer or lacks it).
    pub fn metric(&self, service: &str, name: &str) -> Option<f64> {
        http_get(self.http_port(service), "/metrics").and_then(|body| metric(&body, name))
    }

    /// Zenoh args of a consumer joining the pipeline (the fifth endpoint is its own).
    pub fn consumer_args(&self, listen: bool) -> ZenohArgs {
        ZenohArgs {
            connect: self.endpoints[..4].to_vec(),
            listen: if listen {
                vec![self.endpoints[4].clone()]
            } else {
                Vec::new()
            },
            namespace: self.namespace.clone(),
            ..ZenohArgs::default()
        }
    }

    /// `--namespace` and `--zenoh-connect` of a `conesight` consumer command.
    pub fn cli_args(&self) -> Vec<String> {
        vec![
            "--namespace".into(),
            self.namespace.clone(),
            "--zenoh-connect".into(),
            self.endpoints[..4].join(","),
        ]
    }

    pub fn log(&self) -> String {
        self.processes
            .iter()
            .flatten()
            .map(|p| format!("=== {} ===\n{}", p.name, p.log_text()))
            .collect::<Vec<_>>()
            .join("\n")
    }
}
