# Debian 12 roots for `make package` (sourced by build.sh and test.sh).
#   ensure_root ARCH DIR [PACKAGES]  debootstrap a minbase bookworm root (with
#                                    PACKAGES, comma-separated) into DIR once;
#                                    later calls reuse it
#   ensure_binfmt_arm64              let the kernel run aarch64 programs through
#                                    qemu-user-static (an arm64 root's package
#                                    scripts, the arm64 veneerd)
#   root_mount DIR / root_umount DIR /proc, /dev and /dev/pts for a chroot
# Roots come from the machine's Debian mirror (the one apt uses).

debian_mirror() {
  local m
  m=$(sed -n 's/^URIs: *\(http[^ ]*debian\)\/*$/\1/p' /etc/apt/sources.list.d/debian.sources 2>/dev/null | head -1)
  [ -n "$m" ] || m=$(awk '$1=="deb" && $3=="bookworm" {print $2; exit}' /etc/apt/sources.list 2>/dev/null)
  echo "${m:-http://deb.debian.org/debian}"
}

ensure_binfmt_arm64() {
  local conf=/usr/lib/binfmt.d/qemu-aarch64.conf
  [ -e /proc/sys/fs/binfmt_misc/qemu-aarch64 ] && return 0
  [ -e /proc/sys/fs/binfmt_misc/register ] || mount -t binfmt_misc binfmt_misc /proc/sys/fs/binfmt_misc
  [ -f "$conf" ] || { echo "package: $conf missing (qemu-user-static)" >&2; return 1; }
  echo "package: registering qemu-aarch64 with binfmt_misc (aarch64 programs run through qemu-user-static)"
  cat "$conf" > /proc/sys/fs/binfmt_misc/register
}

ensure_root() {
  local arch="$1" dir="$2" include="${3:-}"
  [ -f "$dir/.veneer-root-ready" ] && return 0
  [ "$arch" = arm64 ] && ensure_binfmt_arm64
  echo "package: debootstrap Debian 12 ($arch, minbase${include:+ + $include}) into $dir (once; reused after)"
  rm -rf "$dir.tmp"
  mkdir -p "$(dirname "$dir")"
  local log="$dir.debootstrap.log"
  if ! debootstrap --arch="$arch" --variant=minbase ${include:+--include="$include"} \
      bookworm "$dir.tmp" "$(debian_mirror)" > "$log" 2>&1; then
    echo "package: debootstrap failed, see $log" >&2; tail -5 "$log" >&2; return 1
  fi
  rm -rf "$dir"; mv "$dir.tmp" "$dir"
  touch "$dir/.veneer-root-ready"
}

root_mount() {
  local dir="$1"
  mountpoint -q "$dir/proc" || mount -t proc proc "$dir/proc"
  mountpoint -q "$dir/dev" || mount --bind /dev "$dir/dev"
  mountpoint -q "$dir/dev/pts" || mount --bind /dev/pts "$dir/dev/pts"
}

root_umount() {
  local dir="$1" m
  for m in dev/pts dev proc; do
    mountpoint -q "$dir/$m" && umount -l "$dir/$m"
  done
  return 0
}
