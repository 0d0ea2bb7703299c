#!/usr/bin/env bash
# Make `qemu-system-arm` available for the Cortex-M4F tests without changing
# the machine's installed packages: if it is not on PATH, Debian's package and
# the libraries it lacks are downloaded (apt-get download, no root needed for
# the files themselves) and unpacked under target/qemu/ (dpkg-deb -x), behind
# a wrapper in target/qemu/bin. Installing the package system-wide can remove
# others (on a machine with a backported qemu-utils it removes qemu-utils), so
# this never calls `apt-get install`.
# Prints the directory to put in front of PATH (empty if qemu is already there).
set -euo pipefail
cd "$(dirname "$0")/.."
if command -v qemu-system-arm >/dev/null 2>&1; then
    exit 0
fi
dest="$PWD/target/qemu"
if [ ! -x "$dest/bin/qemu-system-arm" ]; then
    if ! command -v apt-get >/dev/null 2>&1 || ! command -v dpkg-deb >/dev/null 2>&1; then
        echo "install_qemu.sh: qemu-system-arm is missing and this is not a Debian-like system; install QEMU (qemu-system-arm) yourself" >&2
        exit 1
    fi
    echo "install_qemu.sh: fetching Debian's qemu-system-arm into $dest (no system package is changed)" >&2
    work="$(mktemp -d)" && chmod 755 "$work"
    trap 'rm -rf "$work"' EXIT
    if [ -z "$(ls -A /var/lib/apt/lists 2>/dev/null | grep -v lock)" ]; then
        sudo=""; [ "$(id -u)" -ne 0 ] && sudo="sudo"
        $sudo apt-get update -qq
    fi
    # The packages an install would add (nothing is installed: -s simulates).
    pkgs=$(apt-get install -s --no-install-recommends qemu-system-arm 2>/dev/null | awk '/^Inst /{print $2}')
    [ -n "$pkgs" ] || { echo "install_qemu.sh: apt-get cannot resolve qemu-system-arm" >&2; exit 1; }
    (cd "$work" && apt-get download -q=2 $pkgs 2>&1 | { grep -v "^W: Download is performed unsandboxed" >&2 || true; }) || { echo "install_qemu.sh: apt-get download failed for: $(echo $pkgs)" >&2; exit 1; }
    rm -rf "$dest.partial" && mkdir -p "$dest.partial/root" "$dest.partial/bin"
    for d in "$work"/*.deb; do dpkg-deb -x "$d" "$dest.partial/root"; done
    libs=$(find "$dest.partial/root" -name '*.so*' -printf '%h\n' | sort -u | sed "s#^$dest.partial#$dest#" | tr '\n' ':')
    cat > "$dest.partial/bin/qemu-system-arm" <<WRAP
#!/bin/sh
LD_LIBRARY_PATH="$libs\${LD_LIBRARY_PATH:-}" exec "$dest/root/usr/bin/qemu-system-arm" -L "$dest/root/usr/share/qemu" "\$@"
WRAP
    chmod +x "$dest.partial/bin/qemu-system-arm"
    rm -rf "$dest" && mv "$dest.partial" "$dest"
fi
"$dest/bin/qemu-system-arm" --version >/dev/null
echo "$dest/bin"
