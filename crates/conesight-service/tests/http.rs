//! The health and metrics server over real HTTP on 127.0.0.1 (port 0), probed by the
//! healthcheck helper and a raw HTTP client.

// Test helpers outside #[test] functions unwrap too.
#![allow(clippy::unwrap_used)]

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use conesight_service::{
    HealthcheckArgs, HealthcheckError, HttpLimits, HttpState, Metrics, Readiness, healthcheck,
    router, serve, serve_with,
};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};

async fn raw_get(addr: SocketAddr, path: &str) -> String {
    let mut stream = TcpStream::connect(addr).await.unwrap();
    let request = format!("GET {path} HTTP/1.1\r\nHost: test\r\nConnection: close\r\n\r\n");
    stream.write_all(request.as_bytes()).await.unwrap();
    let mut response = String::new();
    stream.read_to_string(&mut response).await.unwrap();
    response
}

fn probe(addr: SocketAddr) -> HealthcheckArgs {
    HealthcheckArgs {
        addr,
        path: "/readyz".to_owned(),
        timeout_secs: 2.0,
    }
}

#[tokio::test]
async fn livez_readyz_metrics_and_graceful_shutdown() {
    let readiness = Arc::new(Readiness::new(Some(Duration::from_secs(5))));
    let metrics = Arc::new(Metrics::new());
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(serve(
        listener,
        router(HttpState {
            readiness: readiness.clone(),
            metrics: metrics.clone(),
        }),
        async {
            let _ = stopped.await;
        },
    ));

    let livez = raw_get(addr, "/livez").await;
    assert!(livez.starts_with("HTTP/1.1 200"), "{livez}");
    assert!(livez.ends_with("ok\n"));

    // Not ready: nothing loaded, no session, no input.
    let readyz = raw_get(addr, "/readyz").await;
    assert!(readyz.starts_with("HTTP/1.1 503"), "{readyz}");
    assert!(readyz.contains("model_loaded false"));
    match healthcheck(&probe(addr)).await {
        Err(HealthcheckError::Unhealthy {
            status: 503, body, ..
        }) => {
            assert!(body.contains("not ready"), "{body}");
        }
        other => panic!("expected 503, got {other:?}"),
    }

    readiness.set_model_loaded(true);
    readiness.set_session_up(true);
    readiness.mark_input();
    healthcheck(&probe(addr)).await.unwrap();
    // 0.0.0.0 means this host.
    healthcheck(&probe(SocketAddr::from(([0, 0, 0, 0], addr.port()))))
        .await
        .unwrap();

    metrics.frame_received();
    metrics.error("oversize");
    metrics.observe_stage("pnp", Duration::from_micros(250));
    let text = raw_get(addr, "/metrics").await;
    assert!(text.starts_with("HTTP/1.1 200"), "{text}");
    assert!(text.contains("application/openmetrics-text"));
    assert!(text.contains("conesight_frames_received_total 1"));
    assert!(text.contains("conesight_errors_total{kind=\"oversize\"} 1"));
    assert!(text.contains("conesight_stage_latency_seconds_count{stage=\"pnp\"} 1"));

    let missing = raw_get(addr, "/nope").await;
    assert!(missing.starts_with("HTTP/1.1 404"), "{missing}");

    stop.send(()).unwrap();
    tokio::time::timeout(Duration::from_secs(5), server)
        .await
        .unwrap()
        .unwrap()
        .unwrap();
    assert!(matches!(
        healthcheck(&probe(addr)).await,
        Err(HealthcheckError::Io { .. })
    ));
}

#[tokio::test]
async fn healthcheck_rejects_non_http_and_times_out() {
    // A server that answers garbage.
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    tokio::spawn(async move {
        let (mut socket, _) = listener.accept().await.unwrap();
        let mut buffer = [0_u8; 256];
        let _ = socket.read(&mut buffer).await;
        socket.write_all(b"SSH-2.0-nope\r\n").await.unwrap();
    });
    assert!(matches!(
        healthcheck(&probe(addr)).await,
        Err(HealthcheckError::NotHttp { .. })
    ));

    // A server that accepts and never answers.
    let silent = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let silent_addr = silent.local_addr().unwrap();
    let _hold = tokio::spawn(async move {
        let (_socket, _) = silent.accept().await.unwrap();
        tokio::time::sleep(Duration::from_secs(10)).await;
    });
    let args = HealthcheckArgs {
        timeout_secs: 0.2,
        ..probe(silent_addr)
    };
    assert!(matches!(
        healthcheck(&args).await,
        Err(HealthcheckError::Timeout { .. })
    ));
}

/// Reads until the server closes the connection (EOF or reset); false if it is still open
/// after `within`.
async fn closed_within(stream: &mut TcpStream, within: Duration) -> bool {
    let mut buffer = [0_u8; 1024];
    let deadline = tokio::time::Instant::now() + within;
    loop {
        match tokio::time::timeout_at(deadline, stream.read(&mut buffer)).await {
            Err(_) => return false,
            Ok(Ok(0) | Err(_)) => return true,
            Ok(Ok(_)) => {}
        }
    }
}

#[tokio::test]
async fn half_open_and_idle_connections_are_closed_and_capped() {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let limits = HttpLimits {
        header_read_timeout: Duration::from_millis(500),
        max_connections: 8,
    };
    let state = HttpState {
        readiness: Arc::new(Readiness::new(None)),
        metrics: Arc::new(Metrics::new()),
    };
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(serve_with(listener, router(state), limits, async {
        let _ = stopped.await;
    }));

    // 40 clients that connect and send nothing, or half a request line: more than the cap.
    let mut silent = Vec::new();
    for index in 0..40 {
        let mut stream = TcpStream::connect(addr).await.unwrap();
        if index % 2 == 1 {
            stream
                .write_all(b"GET /metrics HTTP/1.1\r\nHo")
                .await
                .unwrap();
        }
        silent.push(stream);
    }
    // A generous bound (the timeout is 0.5 s): every one is closed by the server.
    for (index, stream) in silent.iter_mut().enumerate() {
        assert!(
            closed_within(stream, Duration::from_secs(10)).await,
            "connection {index} still open"
        );
    }

    // A kept-alive connection that goes idle after its answer is closed too.
    let mut idle = TcpStream::connect(addr).await.unwrap();
    idle.write_all(b"GET /livez HTTP/1.1\r\nHost: test\r\n\r\n")
        .await
        .unwrap();
    let mut first = [0_u8; 512];
    let read = idle.read(&mut first).await.unwrap();
    assert!(first[..read].starts_with(b"HTTP/1.1 200"));
    assert!(closed_within(&mut idle, Duration::from_secs(10)).await);

    // The slots are free again: a normal request is answered.
    let livez = raw_get(addr, "/livez").await;
    assert!(livez.starts_with("HTTP/1.1 200"), "{livez}");

    stop.send(()).unwrap();
    tokio::time::timeout(Duration::from_secs(10), server)
        .await
        .unwrap()
        .unwrap()
        .unwrap();
}
