//! `shutdown_signal` resolves on SIGTERM. Its own test binary: the signal goes to this process.

use std::time::Duration;

#[tokio::test]
async fn sigterm_resolves_shutdown_signal() {
    let signal = tokio::spawn(conesight_service::shutdown_signal());
    // Let the task run once so its handlers are installed before the signal is sent.
    tokio::time::sleep(Duration::from_millis(200)).await;
    assert!(!signal.is_finished());
    let status = std::process::Command::new("kill")
        .args(["-TERM", &std::process::id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    tokio::time::timeout(Duration::from_secs(5), signal)
        .await
        .unwrap()
        .unwrap();
}
