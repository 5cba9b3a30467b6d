#!/usr/bin/env bash
# Builds the Debian package of the ferrocat command with dpkg-deb:
#   /usr/bin/ferrocat                         (cargo install --path crates/cli --locked)
#   /usr/share/man/man1/ferrocat*.1.gz        (ferrocat manpages)
#   bash, zsh and fish completions            (ferrocat completions)
#   /usr/share/doc/ferrocat/                  (copyright, README, systemd unit examples)
# and a postinst that grants the binary the three capabilities it needs, so that an ordinary
# user (or a service's) runs it without root: cap_net_raw, cap_sys_nice, cap_ipc_lock.
#
#   scripts/package-deb.sh [OUT_DIR]          (default target/debian; prints the .deb's path)
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-target/debian}"
version=$(sed -n 's/^version = "\(.*\)"/\1/p' Cargo.toml | head -n 1)
arch=$(dpkg --print-architecture)
stage=$(mktemp -d)
trap 'rm -rf "$stage"' EXIT

# The binary, as `cargo install` builds it (the workspace's target folder, so that an earlier
# release build is reused), debug information stripped.
CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$(pwd)/target}" \
  cargo install --quiet --path crates/cli --locked --root "$stage/usr" --no-track
strip --strip-debug "$stage/usr/bin/ferrocat"
bin="$stage/usr/bin/ferrocat"

man="$stage/usr/share/man/man1"
mkdir -p "$man"
"$bin" manpages "$man" 2>/dev/null
rm -f "$man/ferrocat-run.txt"
gzip -9n "$man"/*.1

install -d "$stage/usr/share/bash-completion/completions" "$stage/usr/share/zsh/vendor-completions" \
  "$stage/usr/share/fish/vendor_completions.d"
"$bin" completions bash >"$stage/usr/share/bash-completion/completions/ferrocat"
"$bin" completions zsh >"$stage/usr/share/zsh/vendor-completions/_ferrocat"
"$bin" completions fish >"$stage/usr/share/fish/vendor_completions.d/ferrocat.fish"

doc="$stage/usr/share/doc/ferrocat"
install -d "$doc/examples"
{
  echo "Format: https://www.debian.org/doc/packaging-manuals/copyright-format/1.0/"
  echo "Upstream-Name: ferrocat"
  echo
  echo "Files: *"
  echo "Copyright: 2026 The ferrocat developers"
  echo "License: MIT or Apache-2.0"
  echo
  cat LICENSE-MIT
  echo
  cat LICENSE-APACHE
} >"$doc/copyright"
install -m644 README.md "$doc/README.md"
install -m644 packaging/systemd/*.service "$doc/examples/"

install -d "$stage/DEBIAN"
size=$(du -sk --exclude=DEBIAN "$stage" | cut -f1)
cat >"$stage/DEBIAN/control" <<CONTROL
Package: ferrocat
Version: $version
Architecture: $arch
Maintainer: The ferrocat developers <ferrocat@users.noreply.invalid>
Depends: libc6, libcap2-bin
Section: net
Priority: optional
Installed-Size: $size
Description: EtherCAT master with measured distributed clocks, and a virtual segment
 ferrocat brings EtherCAT segments to OP with distributed clocks and exchanges process data
 on a raw network interface, serves a simulated segment to any master, and reproduces the
 clock-synchronisation experiments of three papers. The binary is given cap_net_raw,
 cap_sys_nice and cap_ipc_lock on installation, so that it runs without root.
CONTROL
cat >"$stage/DEBIAN/postinst" <<'POSTINST'
#!/bin/sh
# Raw frames (cap_net_raw), SCHED_FIFO (cap_sys_nice) and locked memory (cap_ipc_lock) for
# whoever runs ferrocat; nothing else.
set -e
if [ "$1" = configure ] && command -v setcap >/dev/null; then
  setcap cap_net_raw,cap_sys_nice,cap_ipc_lock+ep /usr/bin/ferrocat
fi
POSTINST
chmod 755 "$stage/DEBIAN/postinst"

mkdir -p "$out"
deb="$out/ferrocat_${version}_${arch}.deb"
dpkg-deb --root-owner-group --build "$stage" "$deb" >/dev/null
echo "$deb"
