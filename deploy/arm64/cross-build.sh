#!/usr/bin/env bash
# Cross-compiles the conesight binaries for aarch64 in the toolchain chroot (toolchain.sh):
# Debian's rustc-web 1.96 with its arm64 std, linked by gcc-aarch64-linux-gnu against trixie's
# arm64 glibc and GStreamer. The checkout and the cargo registry are bind-mounted, so crates
# come from crates.io (or the host's cache) and the lockfile is the workspace's own.
#
#   deploy/arm64/cross-build.sh                      # conesight-cli + the four services, release
#   deploy/arm64/cross-build.sh -p conesight-cli     # only these packages
# Binaries in target/aarch64-cross/aarch64-unknown-linux-gnu/release/. Needs root (chroot).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
chroot_dir="$ROOT/build/arm64/toolchain"
[[ -f "$chroot_dir/.conesight-toolchain-ok" ]] || "$ROOT/deploy/arm64/toolchain.sh"

packages=("$@")
if [[ ${#packages[@]} -eq 0 ]]; then
    packages=(-p conesight-cli -p conesight-camera-service -p conesight-detector-service -p conesight-keypoints-service -p conesight-localiser-service)
fi
cargo_home="${CARGO_HOME:-$HOME/.cargo}"
mkdir -p "$cargo_home/registry"

# Bind the checkout (and build/, when it is a link elsewhere) at the same paths inside.
mounts=("$ROOT" "$cargo_home/registry")
build_real="$(readlink -f "$ROOT/build")"
[[ "$build_real" != "$ROOT/build" ]] && mounts+=("$build_real")
mounted=()
cleanup() {
    local i
    for ((i = ${#mounted[@]} - 1; i >= 0; i--)); do umount "${mounted[i]}" || true; done
}
trap cleanup EXIT
for dir in "${mounts[@]}"; do
    mkdir -p "$chroot_dir$dir"
    mount --bind "$dir" "$chroot_dir$dir"
    mounted+=("$chroot_dir$dir")
done
for fs in proc dev; do
    mount --bind "/$fs" "$chroot_dir/$fs"
    mounted+=("$chroot_dir/$fs")
done
cp /etc/resolv.conf "$chroot_dir/etc/resolv.conf"
# The host's CA bundle for cargo's downloads: a TLS-inspecting proxy's CA is trusted on the host
# only, and without it the chroot's cargo fails with "SSL certificate problem: self-signed
# certificate in certificate chain".
host_ca="${CARGO_HTTP_CAINFO:-${SSL_CERT_FILE:-/etc/ssl/certs/ca-certificates.crt}}"
chroot_ca=/etc/ssl/certs/conesight-host-ca.crt
if [[ -f "$host_ca" ]]; then
    cp "$host_ca" "$chroot_dir$chroot_ca"
else
    chroot_ca=/etc/ssl/certs/ca-certificates.crt
fi

triple=aarch64-unknown-linux-gnu
chroot "$chroot_dir" /usr/bin/env -i \
    PATH=/usr/bin:/bin HOME=/root \
    CARGO_HOME=/root/.cargo-cross \
    CARGO_REGISTRIES_CRATES_IO_PROTOCOL=sparse \
    CARGO_HTTP_CAINFO="$chroot_ca" \
    CARGO_TARGET_DIR="$ROOT/target/aarch64-cross" \
    CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc \
    CC_aarch64_unknown_linux_gnu=aarch64-linux-gnu-gcc \
    AR_aarch64_unknown_linux_gnu=aarch64-linux-gnu-ar \
    PKG_CONFIG_ALLOW_CROSS=1 \
    PKG_CONFIG_LIBDIR=/usr/lib/aarch64-linux-gnu/pkgconfig:/usr/share/pkgconfig \
    /bin/sh -euc "mkdir -p /root/.cargo-cross && ln -sfn '$cargo_home/registry' /root/.cargo-cross/registry
        cd '$ROOT' && cargo --version && rustc --version
        cargo build --locked --release --target $triple ${packages[*]}"
echo "cross-build.sh: $ROOT/target/aarch64-cross/$triple/release/"
