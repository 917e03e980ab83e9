#!/usr/bin/env bash
# Makes arm64 binaries run on this x86 host: a qemu-aarch64 new enough for ONNX Runtime,
# binfmt_misc mounted (containers often start without it) and qemu-aarch64 registered with the
# F (fix-binary) flag, so it also runs inside Docker containers and in a debootstrapped rootfs
# with no qemu of its own. Idempotent; needs root.
#
#   deploy/arm64/qemu.sh     # called by build-base.sh --arch arm64 and smoke.sh
#
# Why not simply Debian bookworm's qemu-user-static: qemu before 8.1 hands an aarch64 guest the
# host's x86 /proc/cpuinfo. ONNX Runtime's cpuinfo then finds no Arm core in it and
# dereferences NULL while it sizes the caches: `predict` dies with "qemu: uncaught target
# signal 11" as soon as a session is built (`--version` still runs). qemu >= 8.1 emulates an
# aarch64 /proc/cpuinfo. On an older host the static qemu-aarch64 is taken from Debian
# trixie's qemu-user package, static there (apt-get download with a private source list; the
# host's apt sources are not touched) into build/arm64/qemu/.
# The qemu used is always build/arm64/qemu/qemu-aarch64 (a copy of the host's when it is new
# enough), which smoke.sh --no-docker runs directly.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
dir="$ROOT/build/arm64/qemu"
qemu="$dir/qemu-aarch64"
entry=/proc/sys/fs/binfmt_misc/qemu-aarch64

# "qemu-aarch64 version 10.0.13 (Debian ...)" -> 0 when >= 8.1.
new_enough() {
    local version major minor
    version="$("$1" --version 2>/dev/null | sed -n 's/^qemu-aarch64 version \([0-9]*\)\.\([0-9]*\).*/\1 \2/p')"
    read -r major minor <<<"$version"
    [[ -n "${major:-}" ]] && ((major > 8 || (major == 8 && minor >= 1)))
}

registered() {
    [[ -f "$entry" ]] && grep -q "^interpreter $qemu\$" "$entry" && grep -q '^flags:.*F' "$entry"
}

if [[ -x "$qemu" ]] && new_enough "$qemu" && registered; then
    exit 0
fi
if [[ $(id -u) -ne 0 ]]; then
    echo "qemu.sh: needs root (apt-get, mount binfmt_misc); or run it once with sudo" >&2
    exit 1
fi
mkdir -p "$dir"

if [[ ! -x "$qemu" ]] || ! new_enough "$qemu"; then
    host_qemu=/usr/bin/qemu-aarch64-static
    if [[ ! -x "$host_qemu" ]]; then
        echo "qemu.sh: installing qemu-user-static"
        DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends qemu-user-static
    fi
    if new_enough "$host_qemu"; then
        cp "$host_qemu" "$qemu"
    else
        echo "qemu.sh: the host's $("$host_qemu" --version | head -n 1) gives arm64 guests the x86" \
            "/proc/cpuinfo (ONNX Runtime crashes on it); fetching trixie's (static) qemu-user"
        mirror="${CONESIGHT_DEBIAN_MIRROR:-http://deb.debian.org/debian}"
        apt_dir="$dir/apt"
        mkdir -p "$apt_dir/lists/partial" "$apt_dir/cache/archives/partial"
        echo "deb $mirror trixie main" >"$apt_dir/sources.list"
        apt_opts=(-o "Dir::Etc::SourceList=$apt_dir/sources.list" -o "Dir::Etc::SourceParts=-"
            -o "Dir::State::Lists=$apt_dir/lists" -o "Dir::Cache=$apt_dir/cache"
            -o "APT::Architectures::=amd64" -o "Debug::NoLocking=1")
        apt-get "${apt_opts[@]}" update -q
        (cd "$apt_dir" && apt-get "${apt_opts[@]}" download qemu-user)
        debs=("$apt_dir"/qemu-user_*.deb)
        rm -rf "$apt_dir/extract"
        dpkg-deb -x "${debs[0]}" "$apt_dir/extract"
        # trixie's qemu-user is static (qemu-user-static is a transitional package for it).
        cp -L "$apt_dir/extract/usr/bin/qemu-aarch64" "$qemu"
        rm -rf "$apt_dir/extract" "${debs[@]}"
    fi
fi
if ! new_enough "$qemu"; then
    echo "qemu.sh: $qemu is $("$qemu" --version | head -n 1); need >= 8.1" >&2
    exit 1
fi

if [[ ! -f /proc/sys/fs/binfmt_misc/register ]]; then
    mount -t binfmt_misc binfmt_misc /proc/sys/fs/binfmt_misc
fi
[[ -f "$entry" ]] && echo -1 >"$entry"
# aarch64 ELF executables (e_machine 0xb7), the magic and mask Debian's binfmt entry uses.
magic='\x7fELF\x02\x01\x01\x00\x00\x00\x00\x00\x00\x00\x00\x00\x02\x00\xb7\x00'
mask='\xff\xff\xff\xff\xff\xff\xff\x00\xff\xff\xff\xff\xff\xff\xff\xff\xfe\xff\xff\xff'
echo ":qemu-aarch64:M::$magic:$mask:$qemu:F" >/proc/sys/fs/binfmt_misc/register
if ! registered; then
    echo "qemu.sh: qemu-aarch64 is not registered with binfmt_misc's F flag ($entry)" >&2
    exit 1
fi
echo "qemu.sh: $("$qemu" --version | head -n 1) registered for aarch64 ($(grep '^flags' "$entry"))"
