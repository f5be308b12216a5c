#!/usr/bin/env bash
# The configuration the veneerd packages are built from
# (-DVENEER_BUILD_VIEWER=OFF -DVENEER_BUILD_TESTS=OFF) configures without the
# viewer side and builds veneerd from common/, proto/, firmware/ and
# appliance/ only: no file of viewer/ compiled, no Qt, GoogleTest or FLANN.
set -euo pipefail
src="$1" dir="$2"
rm -rf "$dir"
cmake -S "$src" -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=Release \
  -DVENEER_BUILD_VIEWER=OFF -DVENEER_BUILD_TESTS=OFF > "$dir.log" 2>&1 || { cat "$dir.log"; exit 1; }
cmds=$(ninja -C "$dir" -t commands veneerd)
n=$(grep -c ' -c ' <<< "$cmds")
if grep -E ' -c [^ ]*/viewer/' <<< "$cmds"; then echo "veneerd's daemon-only build compiles viewer/ files (above)"; exit 1; fi
if grep -qiE 'Qt6|gtest|flann' "$dir/CMakeCache.txt"; then
  echo "the daemon-only configuration looked for Qt, GoogleTest or FLANN:"; grep -iE 'Qt6|gtest|flann' "$dir/CMakeCache.txt" | head; exit 1
fi
if ninja -C "$dir" -t targets all | grep -qE '^(veneer|veneer-viewer|veneer_ps|veneer_match|test_[a-z_]*):'; then
  echo "the daemon-only configuration has viewer or test targets"; exit 1
fi
[ "$n" -gt 10 ] || { echo "veneerd builds from only $n compile steps?"; exit 1; }
echo "daemon-only: veneerd from $n compile steps, none in viewer/; no Qt, GoogleTest or FLANN looked for"
rm -rf "$dir" "$dir.log"
