#!/usr/bin/env bash
# Makes arm64 binaries run on this x86 host: Debian's qemu-user-static and binfmt-support
# installed, binfmt_misc mounted (containers often start without it) and qemu-aarch64
# registered with the F (fix-binary) flag, so it also runs inside Docker containers and in a
# debootstrapped rootfs with no qemu of its own. Idempotent; needs root.
#
#   deploy/arm64/qemu.sh     # called by build-base.sh --arch arm64 and smoke.sh
set -euo pipefail

entry=/proc/sys/fs/binfmt_misc/qemu-aarch64
if [[ -x /usr/bin/qemu-aarch64-static && -f "$entry" ]] && grep -q '^flags:.*F' "$entry"; then
    exit 0
fi
if [[ $(id -u) -ne 0 ]]; then
    echo "qemu.sh: needs root (apt-get, mount binfmt_misc); or run it once with sudo" >&2
    exit 1
fi
if [[ ! -x /usr/bin/qemu-aarch64-static ]] || ! command -v update-binfmts >/dev/null; then
    echo "qemu.sh: installing qemu-user-static binfmt-support"
    DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends \
        qemu-user-static binfmt-support
fi
if [[ ! -f /proc/sys/fs/binfmt_misc/register ]]; then
    mount -t binfmt_misc binfmt_misc /proc/sys/fs/binfmt_misc
fi
[[ -f "$entry" ]] || update-binfmts --enable qemu-aarch64 || update-binfmts --import qemu-aarch64
if [[ ! -f "$entry" ]] || ! grep -q '^flags:.*F' "$entry"; then
    echo "qemu.sh: qemu-aarch64 is not registered with binfmt_misc's F flag ($entry);" \
        "see update-binfmts --display qemu-aarch64" >&2
    exit 1
fi
echo "qemu.sh: qemu-aarch64 registered ($(grep '^flags' "$entry"))"
