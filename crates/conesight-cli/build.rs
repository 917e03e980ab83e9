//! Sets `CONESIGHT_GIT_REVISION` (recordings' metadata) from `git rev-parse`, `unknown`
//! outside a checkout.

fn main() {
    let revision = std::process::Command::new("git")
        .args(["rev-parse", "--short=12", "HEAD"])
        .output()
        .ok()
        .filter(|out| out.status.success())
        .and_then(|out| String::from_utf8(out.stdout).ok())
        .map_or_else(|| "unknown".to_owned(), |s| s.trim().to_owned());
    println!("cargo:rustc-env=CONESIGHT_GIT_REVISION={revision}");
    println!("cargo:rerun-if-changed=../../.git/HEAD");
}
