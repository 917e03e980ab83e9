#!/usr/bin/env bash
# The aarch64 cross toolchain, made from Debian packages only (no rustup target, which our
# machines cannot download): a Debian trixie amd64 chroot (debootstrap) holding
#   rustc-web + cargo-web 1.96  (Debian's newer Rust, built for trixie)
#   libstd-rust-web-dev:arm64   (the aarch64 std of exactly that rustc, through multiarch)
#   gcc-aarch64-linux-gnu       (linker and C compiler for -sys crates)
#   libgstreamer*-dev:arm64     (the camera sources link GStreamer)
# Trixie because rustc-web's std needs glibc 2.39 and LLVM 22, which bookworm lacks; so the
# binaries link trixie's arm64 glibc (2.41) and the arm64 base is trixie too (base.sh).
#
#   deploy/arm64/toolchain.sh            # build/arm64/toolchain, skipped when complete
#   deploy/arm64/toolchain.sh --force    # rebuild from scratch
# Needs root (debootstrap, chroot). About 3 min here (a 700-package chroot).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
release="${CONESIGHT_ARM64_RELEASE:-trixie}"
mirror="${DEBIAN_MIRROR:-http://deb.debian.org/debian}"
chroot_dir="$ROOT/build/arm64/toolchain"
stamp="$chroot_dir/.conesight-toolchain-ok"

if [[ "${1:-}" == "--force" ]]; then rm -rf "$chroot_dir"; fi
if [[ -f "$stamp" ]]; then
    echo "toolchain.sh: $chroot_dir is complete ($(cat "$stamp"))"
    exit 0
fi
if [[ $(id -u) -ne 0 ]]; then
    echo "toolchain.sh: needs root (debootstrap, chroot)" >&2
    exit 1
fi
command -v debootstrap >/dev/null || apt-get install -y --no-install-recommends debootstrap

if [[ ! -x "$chroot_dir/usr/bin/apt-get" ]]; then
    rm -rf "$chroot_dir"
    mkdir -p "$chroot_dir"
    echo "toolchain.sh: debootstrap $release (amd64, minbase) into $chroot_dir"
    debootstrap --variant=minbase --include=ca-certificates "$release" "$chroot_dir" "$mirror"
fi

packages=(
    rustc-web cargo-web libstd-rust-web-dev:arm64
    gcc-aarch64-linux-gnu libc6-dev-arm64-cross pkgconf
    libgstreamer1.0-dev:arm64 libgstreamer-plugins-base1.0-dev:arm64
)
cp /etc/resolv.conf "$chroot_dir/etc/resolv.conf"
chroot "$chroot_dir" /bin/sh -euc "
    dpkg --add-architecture arm64
    apt-get update -q
    DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends ${packages[*]}
    apt-get clean
"
version="$(chroot "$chroot_dir" /usr/bin/rustc --version)"
std_rlibs=("$chroot_dir"/usr/lib/rustlib/aarch64-unknown-linux-gnu/lib/libstd-*.rlib)
[[ -f "${std_rlibs[0]}" ]] || {
    echo "toolchain.sh: no aarch64 std in the chroot" >&2
    exit 1
}
echo "$version" >"$stamp"
echo "toolchain.sh: ready: $version with the aarch64-unknown-linux-gnu std"
