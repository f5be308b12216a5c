#!/usr/bin/env bash
# make package-test: the packages of build-package/ (or $1) installed on fresh
# Debian 12 systems, run from where they install.
#   amd64: a fresh minbase Debian 12 root; `apt-get install ./veneerd_*_amd64.deb
#     ./veneer_*_amd64.deb ./veneer-viewer_*_amd64.deb` (dependencies from the
#     mirror); the user, groups, store, conffile, unit, udev rules and desktop
#     entry are where they should be; /usr/bin/veneerd --simulate runs as user
#     veneer on the packaged store and /usr/bin/veneer drives a capture through
#     it (status, press, list, pull, normals); then a purge removes the store.
#   arm64: veneerd_*_arm64.deb's binary is an aarch64 ELF; installed the same
#     way in a fresh arm64 Debian 12 root whose programs run under qemu-user
#     (qemu-user-static through binfmt_misc); its /usr/bin/veneerd --version
#     and a short --simulate capture, driven by the amd64 root's veneer.
# Every check prints one line, "ok: ..." or "FAILED: ..."; the last line counts them.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
src="$(cd "$here/../.." && pwd)"
out="$(cd "${1:-$src/build-package}" && pwd)"
# shellcheck source=roots.sh
. "$here/roots.sh"
version=$(sed -n 's/^project(veneer VERSION \([0-9.]*\).*/\1/p' "$src/CMakeLists.txt")
passed=0; failed=0
ok()   { echo "ok: $*"; passed=$((passed + 1)); }
bad()  { echo "FAILED: $*"; failed=$((failed + 1)); }
check() { local what="$1"; shift; if "$@" > /dev/null 2>&1; then ok "$what"; else bad "$what"; fi; }
step() { printf '\n== package-test: %s\n' "$*"; }

for f in veneerd_${version}_amd64.deb veneer_${version}_amd64.deb veneer-viewer_${version}_amd64.deb \
         veneerd_${version}_arm64.deb; do
  [ -f "$out/$f" ] || { echo "package-test: $out/$f missing: run make package" >&2; exit 1; }
done

amd64="$out/test-root-amd64" arm64="$out/test-root-arm64" pids=()
cleanup() {
  local p
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  for p in "${pids[@]}"; do wait "$p" 2>/dev/null || true; done
  for p in "$amd64/var/cache/apt/archives" "$arm64/var/cache/apt/archives"; do
    mountpoint -q "$p" && umount -l "$p"
  done
  root_umount "$amd64"; root_umount "$arm64"
}
trap cleanup EXIT

# fresh ROOT from the pristine cache: a copy, so every run starts clean.
fresh() {
  local arch="$1" dir="$2"
  ensure_root "$arch" "$out/roots/bookworm-$arch"
  mountpoint -q "$dir/var/cache/apt/archives" && umount -l "$dir/var/cache/apt/archives"
  root_umount "$dir"
  # never delete through a mount (/dev is bound into the root)
  if grep -q " $dir/" /proc/mounts; then echo "package-test: $dir still has mounts" >&2; exit 1; fi
  rm -rf "$dir"
  cp -a "$out/roots/bookworm-$arch" "$dir"
  # downloads are kept between runs (apt's cache, outside the fresh root)
  mkdir -p "$out/roots/apt-cache-$arch/partial"
  rm -rf "$dir/var/cache/apt/archives"; mkdir -p "$dir/var/cache/apt/archives"
  root_mount "$dir"
  mount --bind "$out/roots/apt-cache-$arch" "$dir/var/cache/apt/archives"
}
in_root() { local dir="$1"; shift; chroot "$dir" /usr/bin/env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin HOME=/root LANG=C.UTF-8 "$@"; }
# (for a background daemon: the process itself, so that $! is what to kill)
exec_in_root() { local dir="$1"; shift; exec chroot "$dir" /usr/bin/env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin HOME=/root LANG=C.UTF-8 "$@"; }
apt_install() {
  local dir="$1"; shift
  in_root "$dir" sh -c 'apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "$@"' sh "$@"
}
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
wait_file() { local f="$1" i; for i in $(seq 1800); do [ -s "$f" ] && return 0; sleep 0.1; done; return 1; }

# The arm64 install runs under emulation (minutes): started first, in the
# background, while the amd64 packages are checked.
step "arm64: fresh Debian 12 arm64 root ($arm64), programs under qemu-user"
ensure_binfmt_arm64
fresh arm64 "$arm64"
cp "$out/veneerd_${version}_arm64.deb" "$arm64/tmp/"
echo "installing in the background (under qemu-user): apt-get install ./veneerd_${version}_arm64.deb"
apt_install "$arm64" /tmp/veneerd_${version}_arm64.deb > "$out/test-arm64-install.log" 2>&1 &
arm64_install=$!; pids+=("$arm64_install")

step "amd64: fresh Debian 12 root ($amd64)"
fresh amd64 "$amd64"
cp "$out"/veneerd_${version}_amd64.deb "$out"/veneer_${version}_amd64.deb \
   "$out"/veneer-viewer_${version}_amd64.deb "$amd64/tmp/"
# Without Recommends (no services pulled in), but with qt6-qpa-plugins, which
# libqt6gui6 recommends and a plain `apt install` brings: Qt's platform plugins.
echo "installing: apt-get install ./veneerd_${version}_amd64.deb ./veneer_${version}_amd64.deb ./veneer-viewer_${version}_amd64.deb qt6-qpa-plugins"
if apt_install "$amd64" /tmp/veneerd_${version}_amd64.deb /tmp/veneer_${version}_amd64.deb \
     /tmp/veneer-viewer_${version}_amd64.deb qt6-qpa-plugins > "$out/test-amd64-install.log" 2>&1; then
  ok "amd64: the three packages install with their dependencies ($(grep -c '^Setting up' "$out/test-amd64-install.log") packages set up)"
else
  bad "amd64: install (see $out/test-amd64-install.log)"; tail -20 "$out/test-amd64-install.log"; exit 1
fi
check "amd64: /usr/bin/veneerd, /usr/bin/veneer, /usr/bin/veneer-viewer are on PATH" \
  in_root "$amd64" sh -c '[ "$(command -v veneerd)" = /usr/bin/veneerd ] && [ "$(command -v veneer)" = /usr/bin/veneer ] && [ "$(command -v veneer-viewer)" = /usr/bin/veneer-viewer ]'
check "amd64: system user veneer (home /var/lib/veneer, no login) in groups plugdev, gpio, video" \
  in_root "$amd64" sh -c 'getent passwd veneer | grep -q ":/var/lib/veneer:/usr/sbin/nologin$" && for g in plugdev gpio video; do id -nG veneer | tr " " "\n" | grep -qx $g || exit 1; done'
check "amd64: store /var/lib/veneer is veneer:veneer 0750" \
  in_root "$amd64" sh -c '[ "$(stat -c %U:%G:%a /var/lib/veneer)" = veneer:veneer:750 ]'
check "amd64: /etc/veneer/veneerd.json is a conffile, root:veneer 0640" \
  in_root "$amd64" sh -c 'dpkg-query -W -f="\${Conffiles}" veneerd | grep -q "/etc/veneer/veneerd.json " && [ "$(stat -c %U:%G:%a /etc/veneer/veneerd.json)" = root:veneer:640 ]'
check "amd64: unit /lib/systemd/system/veneerd.service runs /usr/bin/veneerd --config /etc/veneer/veneerd.json as veneer" \
  in_root "$amd64" sh -c 'u=/lib/systemd/system/veneerd.service; grep -qx "ExecStart=/usr/bin/veneerd --config /etc/veneer/veneerd.json" $u && grep -qx User=veneer $u && grep -qx Type=notify $u'
check "amd64: udev rules /lib/udev/rules.d/60-veneer.rules (cameras to plugdev, GPIO chips to gpio)" \
  in_root "$amd64" sh -c 'r=/lib/udev/rules.d/60-veneer.rules; grep -q "GROUP=\"plugdev\"" $r && grep -q "GROUP=\"gpio\"" $r'
check "amd64: desktop entry and icon of veneer-viewer" \
  in_root "$amd64" sh -c 'grep -qx Exec=veneer-viewer /usr/share/applications/veneer-viewer.desktop && grep -qx Icon=veneer-viewer /usr/share/applications/veneer-viewer.desktop && [ -s /usr/share/icons/hicolor/scalable/apps/veneer-viewer.svg ]'
check "amd64: veneerd hue (the Hue bridge setup commands) lists discover, pair, lamps, flash" \
  in_root "$amd64" sh -c 'h=$(veneerd hue --help 2>&1 || true); for c in discover pair lamps flash; do echo "$h" | grep -q $c || exit 1; done'
v=$(in_root "$amd64" veneerd --version 2>&1 || true)
[ "$v" = "veneerd $version" ] && ok "amd64: /usr/bin/veneerd --version: $v" || bad "amd64: veneerd --version printed '$v'"
v=$(in_root "$amd64" veneer --version 2>&1 || true)
[ "$v" = "veneer $version" ] && ok "amd64: /usr/bin/veneer --version: $v" || bad "amd64: veneer --version printed '$v'"
v=$(in_root "$amd64" env QT_QPA_PLATFORM=offscreen veneer-viewer --version 2>&1 || true)
echo "$v" | grep -q "veneer-viewer $version" && ok "amd64: /usr/bin/veneer-viewer --version (Qt, offscreen): $v" \
  || bad "amd64: veneer-viewer --version printed '$v'"

# rig_capture ROOT WHO PORT: the daemon of ROOT (running) captures a set,
# driven by the amd64 root's /usr/bin/veneer; pulls it and makes its normals.
rig_capture() {
  local root="$1" who="$2" port="$3" token="$1/var/lib/veneer/sets/token"
  if ! wait_file "$token"; then bad "$who: veneerd --simulate did not start (no $token)"; return 1; fi
  cp "$token" "$amd64/tmp/token-$who"
  # (a capture under qemu-user takes minutes: --timeout)
  # The API is TLS 1.3: the rig's certificate is pinned by its fingerprint (read here from its store).
  local cert="$1/var/lib/veneer/sets.tls/cert.pem" fp
  if ! wait_file "$cert"; then bad "$who: veneerd made no TLS certificate ($cert)"; return 1; fi
  fp=$(openssl x509 -in "$cert" -noout -fingerprint -sha256 | cut -d= -f2)
  local rig=(--rig "127.0.0.1:$port" --token-file "/tmp/token-$who" --timeout 900 --fingerprint "$fp"
             --known-rigs "/tmp/known-rigs-$who") status
  status=$(in_root "$amd64" veneer rig status "${rig[@]}" 2>&1) && ok "$who: veneer rig status: $(echo "$status" | head -1)" \
    || { bad "$who: veneer rig status: $status"; return 1; }
  in_root "$amd64" veneer rig press "${rig[@]}" --wait > "$out/test-$who-press.log" 2>&1 \
    && ok "$who: veneer rig press --wait: a set captured ($(tail -1 "$out/test-$who-press.log"))" \
    || { bad "$who: veneer rig press (see $out/test-$who-press.log)"; return 1; }
  local id; id=$(in_root "$amd64" veneer rig list "${rig[@]}" 2>/dev/null | awk 'NR==1{print $1}')
  [ -n "$id" ] && ls "$root/var/lib/veneer/sets/$id/set.json" > /dev/null 2>&1 \
    && ok "$who: the set $id is stored in /var/lib/veneer/sets/$id" || { bad "$who: no set in the store"; return 1; }
  in_root "$amd64" rm -rf "/tmp/pull-$who" "/tmp/normals-$who"
  in_root "$amd64" veneer rig pull "$id" --out "/tmp/pull-$who" "${rig[@]}" > "$out/test-$who-pull.log" 2>&1 \
    && [ -f "$amd64/tmp/pull-$who/set.json" ] \
    && ok "$who: veneer rig pull: $(ls "$amd64/tmp/pull-$who" | grep -c '^light_.*\.png$') photos, set.json" \
    || { bad "$who: veneer rig pull (see $out/test-$who-pull.log)"; return 1; }
  in_root "$amd64" veneer normals "/tmp/pull-$who" --out "/tmp/normals-$who" > "$out/test-$who-normals.log" 2>&1 \
    && [ -s "$amd64/tmp/normals-$who/normals.pfm" ] \
    && ok "$who: veneer normals on the pulled set wrote normals.pfm ($(tail -1 "$out/test-$who-normals.log"))" \
    || bad "$who: veneer normals (see $out/test-$who-normals.log)"
}

# simulated_rig <root> <who> <size>: the root's veneerd --simulate as user
# veneer on /var/lib/veneer/sets, driven through rig_capture, then stopped.
simulated_rig() {
  local root="$1" who="$2" size="$3" port
  port=$(free_port)
  exec_in_root "$root" runuser -u veneer -- veneerd --simulate --listen "127.0.0.1:$port" \
    --store /var/lib/veneer/sets --size "$size" > "$out/test-$who-veneerd.log" 2>&1 &
  pids+=($!)
  rig_capture "$root" "$who" "$port" || true
  kill "${pids[-1]}" 2>/dev/null || true; wait "${pids[-1]}" 2>/dev/null || true
}

step "amd64: /usr/bin/veneerd --simulate as user veneer on /var/lib/veneer/sets, driven by /usr/bin/veneer"
simulated_rig "$amd64" amd64 320x212

step "arm64: the binary"
dir="$out/test-deb-arm64"; rm -rf "$dir"; dpkg-deb -x "$out/veneerd_${version}_arm64.deb" "$dir"
elf=$(readelf -h "$dir/usr/bin/veneerd" | sed -n 's/^ *Machine: *//p')
[ "$elf" = AArch64 ] && ok "arm64: usr/bin/veneerd in veneerd_${version}_arm64.deb is an ELF for $elf" \
  || bad "arm64: usr/bin/veneerd is for '$elf', not AArch64"
check "arm64: veneerd_${version}_arm64.deb declares Architecture arm64" \
  sh -c "[ \"\$(dpkg-deb -f '$out/veneerd_${version}_arm64.deb' Architecture)\" = arm64 ]"
if readelf -d "$dir/usr/bin/veneerd" | grep -qiE 'NEEDED.*(Qt6|opencv_calib3d|flann)'; then
  bad "arm64: veneerd links the viewer's libraries"
else
  ok "arm64: veneerd links no Qt, no engine library ($(readelf -d "$dir/usr/bin/veneerd" | grep -c NEEDED) libraries)"
fi

step "arm64: waiting for the install under qemu-user (started first)"
if wait "$arm64_install"; then
  ok "arm64: veneerd installs with its dependencies under qemu-user ($(grep -c '^Setting up' "$out/test-arm64-install.log") packages set up)"
else
  bad "arm64: install (see $out/test-arm64-install.log)"; tail -20 "$out/test-arm64-install.log"
fi
check "arm64: system user veneer, store veneer:veneer 0750, conffile root:veneer 0640" \
  in_root "$arm64" sh -c 'getent passwd veneer >/dev/null && [ "$(stat -c %U:%G:%a /var/lib/veneer)" = veneer:veneer:750 ] && [ "$(stat -c %U:%G:%a /etc/veneer/veneerd.json)" = root:veneer:640 ]'
v=$(in_root "$arm64" veneerd --version 2>&1 || true)
[ "$v" = "veneerd $version" ] && ok "arm64: /usr/bin/veneerd --version under qemu-aarch64: $v" || bad "arm64: veneerd --version printed '$v'"

step "arm64: /usr/bin/veneerd --simulate (under qemu-user) as user veneer, driven by the amd64 root's veneer"
simulated_rig "$arm64" arm64 160x106

step "amd64: purge"
if in_root "$amd64" sh -c 'DEBIAN_FRONTEND=noninteractive apt-get purge -y -qq veneerd' > "$out/test-amd64-purge.log" 2>&1; then
  check "amd64: apt-get purge veneerd removes the program, the store, the config and the unit" \
    in_root "$amd64" sh -c '! [ -e /usr/bin/veneerd ] && ! [ -e /var/lib/veneer ] && ! [ -e /etc/veneer/veneerd.json ] && ! [ -e /lib/systemd/system/veneerd.service ] && ! dpkg-statoverride --list | grep -q veneer'
else
  bad "amd64: apt-get purge veneerd (see $out/test-amd64-purge.log)"
fi

echo
echo "package-test: $passed passed, $failed failed"
[ "$failed" -eq 0 ]
