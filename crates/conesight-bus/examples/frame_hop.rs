//! One bus hop measured alone: a publishing peer session and `--subscribers` subscribing peer
//! sessions in this process on 127.0.0.1 (TCP, shared memory on), a 1920x1200 RGB8 frame
//! written in place (`write_payload`) and a small message, each published at 10 Hz with and
//! without `express`; prints the time to write the payload, to `put` it, and from `put` to the
//! first subscriber's callback, as p50 / p90 in microseconds.
//!
//! ```text
//! cargo run --release -p conesight-bus --example frame_hop [-- --count 100 --subscribers 2]
//! ```

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use conesight_bus::zenoh::Wait;
use conesight_bus::{PayloadStorage, ZenohArgs, open_session, write_payload_infallible};

fn percentile(values: &mut [f64], p: f64) -> f64 {
    values.sort_by(f64::total_cmp);
    if values.is_empty() {
        return f64::NAN;
    }
    values[((values.len() - 1) as f64 * p / 100.0).round() as usize]
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let mut count = 100_usize;
    let mut subscribers = 1_usize;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--count" => count = args.next().unwrap_or_default().parse()?,
            "--subscribers" => subscribers = args.next().unwrap_or_default().parse()?,
            other => anyhow::bail!(
                "unknown argument {other}; usage: frame_hop [--count N] [--subscribers N]"
            ),
        }
    }
    let port = std::net::TcpListener::bind("127.0.0.1:0")?
        .local_addr()?
        .port();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let publisher_session = open_session(&ZenohArgs {
        listen: vec![endpoint.clone()],
        ..ZenohArgs::default()
    })
    .await?;
    let mut subscriber_sessions = Vec::new();
    for _ in 0..subscribers.max(1) {
        subscriber_sessions.push(
            open_session(&ZenohArgs {
                connect: vec![endpoint.clone()],
                listen: vec!["tcp/127.0.0.1:0".to_owned()],
                ..ZenohArgs::default()
            })
            .await?,
        );
    }
    // Each payload with and without `express`, alternating sample by sample (these machines
    // are noisy: blocks measured one after the other differ more than the two settings).
    for (name, bytes) in [
        ("frame 1920x1200 rgb8", 1920 * 1200 * 3 + 64),
        ("small 200 B", 200),
    ] {
        let received: Arc<Mutex<Option<Instant>>> = Arc::default();
        let mut declared = Vec::new();
        let mut publishers = Vec::new();
        for express in [false, true] {
            let key = format!("conesight/bench/hop/{bytes}/{express}");
            for (i, session) in subscriber_sessions.iter().enumerate() {
                let slot = received.clone();
                declared.push(
                    session
                        .declare_subscriber(key.clone())
                        .callback(move |_sample| {
                            if i == 0
                                && let Ok(mut at) = slot.lock()
                            {
                                *at = Some(Instant::now());
                            }
                        })
                        .await
                        .map_err(|e| anyhow::anyhow!("{e}"))?,
                );
            }
            publishers.push(
                publisher_session
                    .declare_publisher(key)
                    .express(express)
                    .await
                    .map_err(|e| anyhow::anyhow!("{e}"))?,
            );
        }
        tokio::time::sleep(Duration::from_millis(500)).await;
        // [batched, express] each: write, put, put -> callback.
        let mut times: [[Vec<f64>; 3]; 2] = Default::default();
        let mut in_shm = 0;
        for i in 0..2 * (count + 5) {
            tokio::time::sleep(Duration::from_millis(100)).await;
            if let Ok(mut at) = received.lock() {
                *at = None;
            }
            let t0 = Instant::now();
            let (payload, storage) =
                write_payload_infallible(&publisher_session, bytes, |buf| buf.fill(i as u8));
            let t1 = Instant::now();
            publishers[i % 2]
                .put(payload)
                .wait()
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            let t2 = Instant::now();
            let arrived = loop {
                if let Some(at) = received.lock().ok().and_then(|at| *at) {
                    break Some(at);
                }
                if t2.elapsed() > Duration::from_millis(500) {
                    break None;
                }
                std::thread::yield_now();
            };
            if i < 10 {
                continue;
            }
            in_shm += usize::from(storage == PayloadStorage::SharedMemory);
            let slot = &mut times[i % 2];
            slot[0].push((t1 - t0).as_secs_f64() * 1e6);
            slot[1].push((t2 - t1).as_secs_f64() * 1e6);
            if let Some(at) = arrived {
                slot[2].push(at.saturating_duration_since(t2).as_secs_f64() * 1e6);
            }
        }
        for (mode, [write_us, put_us, hop_us]) in ["batched", "express"].iter().zip(&mut times) {
            println!(
                "{name}, {mode}: write p50 {:.0} us p90 {:.0}; put p50 {:.0} us p90 {:.0}; put -> callback p50 {:.0} us p90 {:.0} ({} of {count} received)",
                percentile(write_us, 50.0),
                percentile(write_us, 90.0),
                percentile(put_us, 50.0),
                percentile(put_us, 90.0),
                percentile(hop_us, 50.0),
                percentile(hop_us, 90.0),
                hop_us.len()
            );
        }
        println!("  ({in_shm} of {} payloads in shared memory)", 2 * count);
    }
    Ok(())
}
