//! `conesight status`: the live services of a namespace (their liveliness tokens) with each
//! one's `health` answer; `--watch` prints services as they join and leave.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use conesight_bus::zenoh::sample::SampleKind;
use conesight_bus::{ServiceQuery, Topics, ZenohArgs, open_session};
use conesight_pipeline::Shutdown;
use conesight_pipeline::presence::Health;
use serde::Serialize;

/// Arguments of `conesight status`.
#[derive(Debug, clap::Args)]
pub struct StatusArgs {
    /// Zenoh session and keys: `--namespace` and `--vehicle` name the services listed.
    #[command(flatten)]
    zenoh: ZenohArgs,
    /// One JSON object per service (or per join/leave with `--watch`) instead of a table.
    #[arg(long)]
    json: bool,
    /// Keep running and print every service that joins or leaves, until Ctrl-C.
    #[arg(long)]
    watch: bool,
    /// How long to wait for the services' answers, ms.
    #[arg(long = "timeout-ms", default_value_t = 1000)]
    timeout_ms: u64,
}

/// One live service as listed.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct ServiceStatus {
    pub(crate) service: String,
    pub(crate) zid: String,
    /// `null` when the service holds a token but did not answer the health query in time.
    pub(crate) health: Option<Health>,
}

/// One join or leave seen by `--watch`.
#[derive(Debug, Serialize)]
struct Presence<'a> {
    event: &'a str,
    service: &'a str,
    zid: &'a str,
    /// Seconds since `status --watch` started.
    t_s: f64,
}

/// Runs `conesight status`; exit status 1 when no service is live (one-shot mode).
pub fn run(args: &StatusArgs) -> anyhow::Result<std::process::ExitCode> {
    conesight_service::init_tracing();
    let runtime = crate::async_runtime()?;
    runtime.block_on(async {
        let session = open_session(&args.zenoh).await?;
        let topics = Topics::from_args(&args.zenoh)?;
        let result = if args.watch {
            watch(&session, &topics, args).await
        } else {
            list(&session, &topics, args).await
        };
        let _ = session.close().await;
        result
    })
}

async fn list(
    session: &conesight_bus::zenoh::Session,
    topics: &Topics,
    args: &StatusArgs,
) -> anyhow::Result<std::process::ExitCode> {
    let services = live_services(session, topics, Duration::from_millis(args.timeout_ms)).await?;
    if services.is_empty() {
        eprintln!(
            "no conesight service is live in namespace {:?}, vehicle {:?}: check --namespace, \
             --vehicle and --zenoh-connect (the address of a service's --zenoh-listen)",
            topics.namespace(),
            topics.vehicle()
        );
        return Ok(std::process::ExitCode::FAILURE);
    }
    if args.json {
        for service in &services {
            println!("{}", serde_json::to_string(service)?);
        }
    } else {
        print!("{}", table(&services));
    }
    Ok(std::process::ExitCode::SUCCESS)
}

/// The services holding a liveliness token now, each with its health answer.
pub(crate) async fn live_services(
    session: &conesight_bus::zenoh::Session,
    topics: &Topics,
    timeout: Duration,
) -> anyhow::Result<Vec<ServiceStatus>> {
    let tokens = session
        .liveliness()
        .get(topics.all_services()?)
        .timeout(timeout)
        .await
        .map_err(|error| anyhow::anyhow!("liveliness query failed: {error}"))?;
    let mut services: BTreeMap<(String, String), Option<Health>> = BTreeMap::new();
    while let Ok(reply) = tokens.recv_async().await {
        if let Ok(sample) = reply.result()
            && let Some((service, zid)) = topics.parse_service(sample.key_expr().as_str())
        {
            services.insert((service.to_owned(), zid.to_owned()), None);
        }
    }
    if !services.is_empty() {
        let replies = session
            .get(topics.all_services_query(ServiceQuery::Health)?)
            .timeout(timeout)
            .await
            .map_err(|error| anyhow::anyhow!("health query failed: {error}"))?;
        while let Ok(reply) = replies.recv_async().await {
            let Ok(sample) = reply.result() else { continue };
            let Some(token) = sample.key_expr().as_str().strip_suffix("/health") else {
                continue;
            };
            let Some((service, zid)) = topics.parse_service(token) else {
                continue;
            };
            match serde_json::from_slice::<Health>(&sample.payload().to_bytes()) {
                Ok(health) => {
                    if let Some(slot) = services.get_mut(&(service.to_owned(), zid.to_owned())) {
                        *slot = Some(health);
                    }
                }
                Err(error) => tracing::warn!(%service, %zid, %error, "undecodable health answer"),
            }
        }
    }
    Ok(services
        .into_iter()
        .map(|((service, zid), health)| ServiceStatus {
            service,
            zid,
            health,
        })
        .collect())
}

fn table(services: &[ServiceStatus]) -> String {
    let mut text = format!(
        "{:<10} {:<34} {:<9} {:>12} {:>10} {:>9}\n",
        "service", "zid", "ready", "input age s", "processed", "dropped"
    );
    for status in services {
        let (ready, age, processed, dropped) = match &status.health {
            Some(health) => (
                if health.ready { "ready" } else { "not ready" }.to_owned(),
                health
                    .input_age_secs
                    .map_or_else(|| "-".to_owned(), |age| format!("{age:.3}")),
                health.frames_processed.to_string(),
                health.frames_dropped.to_string(),
            ),
            None => ("no answer".into(), "-".into(), "-".into(), "-".into()),
        };
        text.push_str(&format!(
            "{:<10} {:<34} {:<9} {:>12} {:>10} {:>9}\n",
            status.service, status.zid, ready, age, processed, dropped
        ));
    }
    text
}

async fn watch(
    session: &conesight_bus::zenoh::Session,
    topics: &Topics,
    args: &StatusArgs,
) -> anyhow::Result<std::process::ExitCode> {
    let shutdown = Shutdown::new();
    shutdown.trigger_on_signal();
    let started = Instant::now();
    let subscriber = session
        .liveliness()
        .declare_subscriber(topics.all_services()?)
        .history(true)
        .await
        .map_err(|error| anyhow::anyhow!("liveliness subscriber failed: {error}"))?;
    loop {
        let sample = tokio::select! {
            () = shutdown.wait() => break,
            sample = subscriber.recv_async() => match sample {
                Ok(sample) => sample,
                Err(_) => break,
            },
        };
        let Some((service, zid)) = topics.parse_service(sample.key_expr().as_str()) else {
            continue;
        };
        let event = Presence {
            event: if sample.kind() == SampleKind::Put {
                "join"
            } else {
                "leave"
            },
            service,
            zid,
            t_s: started.elapsed().as_secs_f64(),
        };
        if args.json {
            println!("{}", serde_json::to_string(&event)?);
        } else {
            println!(
                "{:>9.3} s  {:<5} {:<10} {}",
                event.t_s, event.event, event.service, event.zid
            );
        }
    }
    Ok(std::process::ExitCode::SUCCESS)
}
