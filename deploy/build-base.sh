#!/usr/bin/env bash
# Builds the base image every service image starts FROM: a minimal Debian rootfs made with
# debootstrap (--variant=minbase), trimmed, and imported with `docker import`. No registry is
# needed, only a Debian mirror.
#
#   deploy/build-base.sh                 # conesight/base:<host release>, skipped if it exists
#   deploy/build-base.sh --force         # rebuild even if the image exists
#   deploy/build-base.sh --arch arm64 --release trixie  # foreign arch (Jetson): qemu-user + binfmt (qemu.sh); deploy/arm64/
#   deploy/build-base.sh --release bookworm  # on a non-Debian host (Ubuntu, L4T)
#
# The service binaries are built on the host and linked against the host's glibc, so the base
# defaults to the host's Debian release (VERSION_CODENAME in /etc/os-release). The rootfs and
# its tarball stay in build/base/ (git-ignored). Needs root (debootstrap creates device nodes
# and chroots); uses sudo when not root.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"

release=""
arch=""
mirror="${DEBIAN_MIRROR:-http://deb.debian.org/debian}"
force=0

usage() {
    sed -n '2,15p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
}

while [[ $# -gt 0 ]]; do
    case "$1" in
        --force) force=1 ;;
        --release) release="$2"; shift ;;
        --arch) arch="$2"; shift ;;
        --mirror) mirror="$2"; shift ;;
        -h | --help) usage; exit 0 ;;
        *) echo "build-base.sh: unknown argument: $1" >&2; usage >&2; exit 2 ;;
    esac
    shift
done

if [[ -z "$release" ]]; then
    # shellcheck disable=SC1091
    release="$(. /etc/os-release; if [[ "${ID:-}" == debian ]]; then echo "${VERSION_CODENAME:-}"; fi)"
fi
if [[ -z "$release" ]]; then
    # Not Debian (a Jetson's L4T is Ubuntu): say which Debian release to build, one whose glibc
    # is at least the one the binaries were linked against (bookworm: 2.36).
    echo "build-base.sh: the host is not Debian; pass --release (e.g. --release bookworm)" >&2
    exit 2
fi
host_arch="$(dpkg --print-architecture)"
arch="${arch:-$host_arch}"

tag="conesight/base:${release}"
[[ "$arch" != "$host_arch" ]] && tag="${tag}-${arch}"

if [[ $force -eq 0 ]] && docker image inspect "$tag" >/dev/null 2>&1; then
    echo "build-base.sh: $tag exists (use --force to rebuild)"
    exit 0
fi

SUDO=()
if [[ $(id -u) -ne 0 ]]; then
    if command -v sudo >/dev/null; then SUDO=(sudo); else
        echo "build-base.sh: needs root or sudo (debootstrap)" >&2
        exit 1
    fi
fi

if ! command -v debootstrap >/dev/null; then
    echo "build-base.sh: installing debootstrap"
    "${SUDO[@]}" apt-get install -y --no-install-recommends debootstrap
fi

work="$ROOT/build/base/${release}-${arch}"
rootfs="$work/rootfs"
tarball="$work/rootfs.tar"
"${SUDO[@]}" rm -rf "$rootfs" "$tarball"
mkdir -p "$work"

foreign=()
if [[ "$arch" != "$host_arch" ]]; then
    # debootstrap runs the second stage inside the chroot, which needs the target's binaries to
    # execute here: qemu-user >= 8.1 registered with binfmt_misc, flag F (deploy/arm64/qemu.sh).
    foreign=(--foreign)
    [[ "$arch" == arm64 ]] && "${SUDO[@]}" "$ROOT/deploy/arm64/qemu.sh"
fi

# The camera service and the CLI link GStreamer (camera sources `gst:` and `video:`): its
# libraries and the base and good plugins (v4l2src, videoconvert, decodebin, jpegdec, ...) at
# run time; the -dev packages stay on the build host (scripts/setup.sh).
# dbus-x11: a dbus-session-bus for dconf-service (pulled in by gstreamer1.0-plugins-good through
# libsoup and glib-networking); without it debootstrap failed configuring dconf-service.
runtime_packages="libgstreamer1.0-0,libgstreamer-plugins-base1.0-0,gstreamer1.0-plugins-base,gstreamer1.0-plugins-good,dbus-x11"

echo "build-base.sh: debootstrap $release ($arch, minbase) into $rootfs"
"${SUDO[@]}" debootstrap --variant=minbase --arch="$arch" "${foreign[@]}" \
    --include="$runtime_packages" "$release" "$rootfs" "$mirror"

if [[ ${#foreign[@]} -gt 0 ]]; then
    # binfmt's flag F (qemu.sh's and Debian's qemu-user-static's): the kernel holds the
    # interpreter open, so the chroot needs no copy of qemu.
    qemu_arch="$(case "$arch" in arm64) echo aarch64 ;; *) echo "$arch" ;; esac)"
    if [[ ! -e "/proc/sys/fs/binfmt_misc/qemu-$qemu_arch" ]]; then
        echo "build-base.sh: no binfmt_misc entry qemu-$qemu_arch: install qemu-user-static" >&2
        exit 1
    fi
    "${SUDO[@]}" chroot "$rootfs" /debootstrap/debootstrap --second-stage
fi

# Trim what a service container never uses (as Debian's own -slim images do): package lists
# and caches, documentation, man pages, locales other than C.
echo "build-base.sh: trimming"
"${SUDO[@]}" rm -rf \
    "$rootfs"/var/lib/apt/lists/* \
    "$rootfs"/var/cache/apt/* \
    "$rootfs"/var/cache/debconf/*-old \
    "$rootfs"/var/log/* \
    "$rootfs"/usr/share/doc/* \
    "$rootfs"/usr/share/man/* \
    "$rootfs"/usr/share/info/* \
    "$rootfs"/usr/share/locale/* \
    "$rootfs"/usr/share/lintian \
    "$rootfs"/tmp/* \
    "$rootfs"/debootstrap
# The image has no network configuration of its own: Docker bind-mounts these at run time.
"${SUDO[@]}" truncate -s 0 "$rootfs/etc/hostname" "$rootfs/etc/resolv.conf" 2>/dev/null || true

"${SUDO[@]}" tar --numeric-owner -C "$rootfs" -cf "$tarball" .
echo "build-base.sh: importing $tag"
if [[ "$arch" == "$host_arch" ]]; then
    docker import \
        --change 'ENV LANG=C.UTF-8' \
        --change 'CMD ["/bin/bash"]' \
        --message "debootstrap --variant=minbase $release $arch" \
        "$tarball" "$tag"
else
    # `docker import --platform` is ignored by Docker 20.10 (the image says amd64, and the first
    # COPY onto it fails with "does not match the specified platform"); a FROM scratch build with
    # --platform records the architecture.
    context="$work/context"
    rm -rf "$context"
    mkdir -p "$context"
    ln -f "$tarball" "$context/rootfs.tar"
    printf '%s\n' 'FROM scratch' 'ADD rootfs.tar /' 'ENV LANG=C.UTF-8' 'CMD ["/bin/bash"]' \
        >"$context/Dockerfile"
    DOCKER_BUILDKIT=0 docker build --quiet --platform "linux/$arch" \
        --label "org.opencontainers.image.description=debootstrap --variant=minbase $release $arch" \
        -t "$tag" "$context"
    rm -rf "$context"
fi
docker image ls "$tag"
