#!/usr/bin/env bash
# make package: Debian packages of Veneer, into build-package/ (or $1).
#   veneerd_<ver>_arm64.deb   the rig daemon for the board (Raspberry Pi OS /
#                             Debian 12 arm64), cross-built with Debian's
#                             aarch64 toolchain against an arm64 Debian 12 root
#   veneerd_<ver>_amd64.deb   the same daemon for an x86-64 rig (any x86-64)
#   veneer_<ver>_amd64.deb    the command line (AVX2 + FMA, as `make` builds it)
#   veneer-viewer_<ver>_amd64.deb  the Qt 6 desktop program, desktop entry, icon
# The daemon packages are built daemon-only (-DVENEER_BUILD_VIEWER=OFF): no
# viewer engine, no Qt. Files come from `cmake --install --component`
# (daemon, cli, viewer); the Debian metadata from tools/package/debian/;
# Depends from dpkg-shlibdeps (for arm64, run inside the arm64 root, whose
# dpkg database knows the arm64 libraries); then every package goes through
# lintian (overrides, each with its reason, in tools/package/debian/*.lintian-overrides).
# Needs root (debootstrap, chroot) and tools/debian-packages-package.txt.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
src="$(cd "$here/../.." && pwd)"
out="$(mkdir -p "${1:-$src/build-package}" && cd "${1:-$src/build-package}" && pwd)"
jobs="${JOBS:-$(nproc)}"
# shellcheck source=roots.sh
. "$here/roots.sh"

version=$(sed -n 's/^project(veneer VERSION \([0-9.]*\).*/\1/p' "$src/CMakeLists.txt")
maintainer="Veneer maintainers <$(git -C "$src" log -1 --format=%ae 2>/dev/null || echo maintainers@localhost)>"
# Reproducible: every file's time and the changelog's date are the commit's.
export SOURCE_DATE_EPOCH="${SOURCE_DATE_EPOCH:-$(git -C "$src" log -1 --format=%ct 2>/dev/null || date +%s)}"
commit=$(git -C "$src" rev-parse --short HEAD 2>/dev/null || echo unknown)
step() { printf '\n== package: %s\n' "$*"; }

launcher=()
if command -v ccache >/dev/null; then
  launcher=(-DCMAKE_C_COMPILER_LAUNCHER=ccache -DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
fi
cmake_common=(-G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_INSTALL_PREFIX=/usr
  -DVENEER_SYSTEMD_UNITDIR=/lib/systemd/system -DVENEER_UDEV_RULESDIR=/lib/udev/rules.d
  -DVENEER_BUILD_TESTS=OFF "${launcher[@]}")
# Debian's hardening flags for ARCH (dpkg-buildflags, hardening=+all: stack
# protector, _FORTIFY_SOURCE, format checks, RELRO and BIND_NOW, and on arm64
# branch protection), less its -g and -O2: the tree's Release flags (-O3) stay.
buildflags() {
  local arch="$1" get
  get() { (cd "$src" && DEB_HOST_ARCH="$arch" DEB_BUILD_MAINT_OPTIONS=hardening=+all dpkg-buildflags --get "$1"); }
  local cflags; cflags="$(get CPPFLAGS) $(get CXXFLAGS | sed -e 's/\(^\| \)-g\( \|$\)/ /' -e 's/\(^\| \)-O2\( \|$\)/ /')"
  printf '%s\n' "-DCMAKE_C_FLAGS=$cflags" "-DCMAKE_CXX_FLAGS=$cflags" \
    "-DCMAKE_EXE_LINKER_FLAGS=$(get LDFLAGS)" "-DCMAKE_SHARED_LINKER_FLAGS=$(get LDFLAGS)" \
    "-DCMAKE_MODULE_LINKER_FLAGS=$(get LDFLAGS)"  # (the video module, libveneer_video.so, is a MODULE)
}
mapfile -t flags_arm64 < <(buildflags arm64)
mapfile -t flags_amd64 < <(buildflags amd64)

# The arm64 libraries veneerd builds against: an arm64 Debian 12 root (the
# compiler's sysroot). Installing them multiarch on this machine is not
# possible: libopencv-imgcodecs-dev:arm64 pulls gdal-plugins:arm64, which
# cannot sit beside the amd64 one that the host's OpenCV needs.
sysroot="$out/roots/sysroot-arm64"
sysroot_packages="libc6-dev,libstdc++-12-dev,dpkg-dev,libopencv-core-dev,libopencv-imgproc-dev,\
libopencv-imgcodecs-dev,libopencv-videoio-dev,libtbb-dev,libspdlog-dev,libfmt-dev,libprotobuf-dev,\
libcurl4-openssl-dev,libgphoto2-dev,libusb-1.0-0-dev,libgpiod-dev,libsystemd-dev,libavahi-client-dev,\
libraw-dev,libdeflate-dev,nlohmann-json3-dev,libcli11-dev,libasio-dev,libssl-dev"
step "arm64 root for cross-building ($sysroot)"
ensure_root arm64 "$sysroot" "$sysroot_packages"
# Its absolute symlinks (libm.so -> /lib/aarch64-linux-gnu/libm.so.6, the
# alternatives of BLAS and LAPACK) would point at this machine's files: made
# relative, so they resolve inside the root (else CMake picks libm.a, and the
# linker misses liblapack.so.3).
find "$sysroot/usr/lib" "$sysroot/etc/alternatives" -type l -lname '/*' -print0 |
  while IFS= read -r -d '' link; do
    ln -sfn "$(realpath -m -s --relative-to="$(dirname "$link")" "$sysroot$(readlink "$link")")" "$link"
  done

step "building veneerd for arm64 (cross, daemon only)"
cmake -S "$src" -B "$out/build-arm64" "${cmake_common[@]}" "${flags_arm64[@]}" -DVENEER_BUILD_VIEWER=OFF \
  -DCMAKE_TOOLCHAIN_FILE="$here/toolchain-arm64.cmake" -DVENEER_ARM64_SYSROOT="$sysroot" > "$out/build-arm64.cmake.log"
nice cmake --build "$out/build-arm64" -j "$jobs" --target veneerd

step "building veneerd for amd64 (daemon only, any x86-64)"
cmake -S "$src" -B "$out/build-amd64-daemon" "${cmake_common[@]}" "${flags_amd64[@]}" -DVENEER_BUILD_VIEWER=OFF \
  -DVENEER_AVX2=OFF > "$out/build-amd64-daemon.cmake.log"
nice cmake --build "$out/build-amd64-daemon" -j "$jobs" --target veneerd

step "building veneer and veneer-viewer for amd64"
cmake -S "$src" -B "$out/build-amd64" "${cmake_common[@]}" "${flags_amd64[@]}" > "$out/build-amd64.cmake.log"
nice cmake --build "$out/build-amd64" -j "$jobs" --target veneer veneer-viewer

# stage PACKAGE ARCH BUILD COMPONENT: the installed tree of one package.
stage() {
  local pkg="$1" arch="$2" build="$3" component="$4" dir="$out/stage/$1_$2"
  rm -rf "$dir"; mkdir -p "$dir"
  DESTDIR="$dir" cmake --install "$build" --component "$component" > /dev/null
  echo "$dir"
}

# man page from the program's --help and --version (help2man), run on the
# amd64 build (the arm64 one prints the same text).
manpage() {
  local dir="$1" prog="$2" exe="$3" what="$4"
  mkdir -p "$dir/usr/share/man/man1"
  QT_QPA_PLATFORM=offscreen help2man --no-info --no-discard-stderr --version-string="$version" \
    --name="$what" "$exe" > "$dir/usr/share/man/man1/$prog.1"
  gzip -9n "$dir/usr/share/man/man1/$prog.1"
}

# docs PACKAGE DIR: copyright, the native changelog; other docs over 4 kB
# gzipped (Debian policy 12.3).
docs() {
  local pkg="$1" dir="$2" doc="$2/usr/share/doc/$1"
  mkdir -p "$doc"
  install -m 0644 "$here/debian/copyright" "$doc/copyright"
  {
    echo "$pkg ($version) bookworm; urgency=medium"
    echo
    echo "  * Built from the Veneer tree at commit $commit."
    echo
    echo " -- $maintainer  $(date -u -R -d "@$SOURCE_DATE_EPOCH")"
  } > "$doc/changelog"
  gzip -9n "$doc/changelog"
  find "$doc" -type f ! -name copyright ! -name '*.gz' -size +4k -exec gzip -9n {} \;
  if [ -f "$here/debian/$pkg.lintian-overrides" ]; then
    install -D -m 0644 "$here/debian/$pkg.lintian-overrides" "$dir/usr/share/lintian/overrides/$pkg"
  fi
}

# shlibs ARCH DIR BINARY...: the Depends dpkg-shlibdeps derives from the
# binaries' libraries (their packages' symbols/shlibs files).
shlibs() {
  local arch="$1" dir="$2"; shift 2
  local work="$out/shlibdeps" rel args=() line
  rm -rf "$work"; mkdir -p "$work/debian"
  printf 'Source: veneer\n\nPackage: veneer\nArchitecture: any\n' > "$work/debian/control"
  if [ "$arch" = arm64 ]; then
    # inside the arm64 root: its dpkg knows which package holds each library
    local inroot="$sysroot/tmp/veneer-shlibdeps"
    rm -rf "$inroot"; mkdir -p "$inroot/debian" "$inroot/pkg/DEBIAN"
    cp "$work/debian/control" "$inroot/debian/"
    for rel in "$@"; do install -D "$dir/$rel" "$inroot/pkg/$rel"; args+=("-epkg/$rel"); done
    line=$(chroot "$sysroot" env DEB_BUILD_ARCH=arm64 DEB_HOST_ARCH=arm64 sh -c "cd /tmp/veneer-shlibdeps && dpkg-shlibdeps -O ${args[*]}")
    rm -rf "$inroot"
  else
    for rel in "$@"; do args+=("-e$dir/$rel"); done
    line=$(cd "$work" && dpkg-shlibdeps -O "${args[@]}")
  fi
  echo "${line#shlibs:Depends=}"
}

# elf_files DIR: every ELF object the staged tree holds (programs, and modules
# such as <libdir>/veneer/libveneer_video.so), relative to DIR, one a line.
elf_files() {
  local dir="$1" rel
  (cd "$dir" && find . -path ./DEBIAN -prune -o -type f -printf '%P\n' | sort) | while IFS= read -r rel; do
    if [ "$(head -c 4 "$dir/$rel" | od -An -c | tr -d ' ')" = '177ELF' ]; then echo "$rel"; fi
  done
}

# strip_elf ARCH DIR: strips every ELF object in the staged tree, as Debian
# ships them (dh_strip: --strip-unneeded, no .comment or .note); a module
# listed nowhere is stripped too (issue 49: libveneer_video.so was not).
strip_elf() {
  local arch="$1" dir="$2" strip=strip rel
  [ "$arch" = arm64 ] && strip=aarch64-linux-gnu-strip
  elf_files "$dir" | while IFS= read -r rel; do
    $strip --strip-unneeded --remove-section=.comment --remove-section=.note "$dir/$rel"
  done
}

# deb PACKAGE ARCH DIR: control files, strip, build, into $out. Every ELF
# object of the tree is stripped and goes to dpkg-shlibdeps.
deb() {
  local pkg="$1" arch="$2" dir="$3"
  local s elf=()
  strip_elf "$arch" "$dir"
  mapfile -t elf < <(elf_files "$dir")
  [ "${#elf[@]}" -gt 0 ] || { echo "package: $pkg: no program in $dir" >&2; exit 1; }
  mkdir -p "$dir/DEBIAN"  # (dpkg-shlibdeps finds the package's root by it)
  local depends; depends=$(shlibs "$arch" "$dir" "${elf[@]}")
  local size; size=$(du -k -s --apparent-size --exclude=DEBIAN "$dir" | cut -f1)
  sed -e "s|@VERSION@|$version|" -e "s|@ARCH@|$arch|" -e "s|@MAINTAINER@|$maintainer|" \
      -e "s|@SIZE@|$size|" -e "s|@SHLIBS@|$depends|" "$here/debian/$pkg.control" > "$dir/DEBIAN/control"
  for s in postinst prerm postrm; do
    [ -f "$here/debian/$pkg.$s" ] && install -m 0755 "$here/debian/$pkg.$s" "$dir/DEBIAN/$s"
  done
  if [ -d "$dir/etc" ]; then
    (cd "$dir" && find etc -type f | sed 's|^|/|' | sort) > "$dir/DEBIAN/conffiles"
  fi
  (cd "$dir" && find . -path ./DEBIAN -prune -o -type f -printf '%P\0' | sort -z | xargs -0 md5sum) > "$dir/DEBIAN/md5sums"
  find "$dir" -type d -exec chmod 0755 {} +
  find "$dir" -newermt "@$SOURCE_DATE_EPOCH" -exec touch -h -d "@$SOURCE_DATE_EPOCH" {} +
  local file="$out/${pkg}_${version}_${arch}.deb"
  dpkg-deb --root-owner-group -Zxz --build "$dir" "$file" > /dev/null
  echo "package: $file  (Depends: $(sed -n 's/^Depends: //p' "$dir/DEBIAN/control"))"
}

step "staging and building the packages"
rm -f "$out"/*.deb
for arch in arm64 amd64; do
  build="$out/build-$arch"; [ "$arch" = amd64 ] && build="$out/build-amd64-daemon"
  dir=$(stage veneerd "$arch" "$build" daemon)
  # The store: owned by the user veneer (postinst, dpkg-statoverride).
  mkdir -p "$dir/var/lib/veneer"
  # Shipped 0644 root:root; postinst makes it root:veneer 0640 (it holds the
  # Hue bridge's key).
  chmod 0644 "$dir/etc/veneer/veneerd.json"
  manpage "$dir" veneerd "$out/build-amd64-daemon/bin/veneerd" "Veneer capture rig daemon"
  docs veneerd "$dir"
  deb veneerd "$arch" "$dir"
done
dir=$(stage veneer amd64 "$out/build-amd64" cli)
manpage "$dir" veneer "$out/build-amd64/bin/veneer" "Veneer appearance transfer, command line"
docs veneer "$dir"
deb veneer amd64 "$dir"
dir=$(stage veneer-viewer amd64 "$out/build-amd64" viewer)
desktop-file-validate "$dir/usr/share/applications/veneer-viewer.desktop"
manpage "$dir" veneer-viewer "$out/build-amd64/bin/veneer-viewer" "Veneer appearance transfer, desktop viewer"
docs veneer-viewer "$dir"
deb veneer-viewer amd64 "$dir"

step "lintian"
# --fail-on error,warning: an unexplained warning fails the build; the
# overrides files say why each remaining tag stays.
lintian --fail-on error,warning --display-info --show-overrides "$out"/*.deb | tee "$out/lintian.txt"
echo "package: lintian: $(grep -c '^[EW]:' "$out/lintian.txt" || true) errors/warnings," \
     "$(grep -c '^I:' "$out/lintian.txt" || true) info, $(grep -c '^O:' "$out/lintian.txt" || true) overridden"

step "done"
for f in "$out"/*.deb; do
  printf '%s  %s\n' "$(du -h "$f" | cut -f1)" "$f"
done
