#!/usr/bin/env bash
# make demo: the main job on the simulated rig.
#  1. start veneerd --simulate (Hue bridge emulator, ray-traced camera, button)
#  2. press the rig's button twice: destination (bull), then source (orange)
#  3. pull both sets over the rig API
#  4. photometric stereo on each (normal maps, albedo, masks)
#  5. correspondence map (method combined) + the destination repainted in the source's look
#  6. a few live-view frames of the source, repainted onto the destination
#  7. the thesis's figures 5.2-5.13 re-made on the simulated pairs (they need
#     no rig: made meanwhile, from the start, while the rig's steps mostly
#     wait on its lamps and camera; printed when the steps before are done)
#  8. with a display: veneer-viewer connected to the simulated rig
# Everything it writes lands in demo-out/. It runs build/bin/veneerd and
# build/bin/veneer: `make demo` builds only those, not the tests and benchmarks;
# with a display it also opens veneer-viewer when `make` has built it.
set -euo pipefail
build="${1:-build}"
root="$(cd "$(dirname "$0")/.." && pwd)"
bin="$root/$build/bin"
out="$root/demo-out"
size="${VENEER_DEMO_SIZE:-1024x680}"
rm -rf "$out"; mkdir -p "$out"
step() { printf '\n== %s\n' "$*"; }

port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
store="$out/rig-store"
step "starting the simulated rig on 127.0.0.1:$port (store $store)"
# The API is TLS 1.3: the rig's certificate (made now, beside its store) is pinned
# by its fingerprint, in a known-rigs file of the demo's own (not ~/.config).
fingerprint=$("$bin/veneerd" --fingerprint --simulate --store "$store" 2>/dev/null)
export VENEER_KNOWN_RIGS="$out/known_rigs"
echo "rig certificate fingerprint (SHA-256): $fingerprint"
"$bin/veneerd" --simulate --scenes bull,orange --listen "127.0.0.1:$port" --store "$store" \
  --size "$size" > "$out/veneerd.log" 2>&1 &
rig_pid=$!
figures_pid=""
cleanup() {
  for pid in "$rig_pid" $figures_pid; do kill "$pid" 2>/dev/null || true; wait "$pid" 2>/dev/null || true; done
}
trap cleanup EXIT
for _ in $(seq 100); do [ -f "$store/token" ] && break; sleep 0.1; done
rig=(--rig "127.0.0.1:$port" --token-file "$store/token" --fingerprint "$fingerprint")
"$bin/veneer" figures --out "$out/figures" > "$out/figures.log" 2>&1 &
figures_pid=$!
"$bin/veneer" rig status "${rig[@]}"

step "button press 1: capture the destination (bull)"
"$bin/veneer" rig press "${rig[@]}" --wait
step "button press 2: capture the source (orange)"
"$bin/veneer" rig press "${rig[@]}" --wait
"$bin/veneer" rig list "${rig[@]}" | tee "$out/sets.txt"
dst_id=$(awk 'NR==1{print $1}' "$out/sets.txt")
src_id=$(awk 'NR==2{print $1}' "$out/sets.txt")

step "pulling both sets"
# --truth: the simulated rig's truth/, for the quality the steps below print (a user's pull has none)
"$bin/veneer" rig pull "$dst_id" --truth --out "$out/destination" "${rig[@]}"
"$bin/veneer" rig pull "$src_id" --truth --out "$out/source" "${rig[@]}"

step "photometric stereo"
"$bin/veneer" normals "$out/destination" --out "$out/destination-normals"
"$bin/veneer" normals "$out/source" --out "$out/source-normals"

step "correspondence map + repaint: veneer transfer --method combined (the default: the motion when the destination is the source moved, else coherent chunks of the nearest normals), painted in the shaded look (the default: the source's texture under the destination's shading)"
"$bin/veneer" transfer --method combined --dst "$out/destination" --src "$out/source" --out "$out/transfer"
"$bin/veneer" inspect --dst "$out/destination" --src "$out/source" --map "$out/transfer" --out "$out/transfer/inspect.png"

step "live view: the source under a moving hand-held lamp, repainted onto the destination"
"$bin/veneer" rig live "${rig[@]}" --frames 12 --fps 6 --out "$out/live" --sweep \
  --map "$out/transfer" --src "$out/source" --dst "$out/destination"

step "the thesis's figures on the simulated pairs"
figures_ok=0; wait "$figures_pid" || figures_ok=$?
figures_pid=""
cat "$out/figures.log"
[ "$figures_ok" -eq 0 ] || { echo "demo: veneer figures failed (exit $figures_ok)" >&2; exit 1; }

if [ -n "${DISPLAY:-}" ] && [ ! -x "$bin/veneer-viewer" ]; then
  step "veneer-viewer is not built (make demo builds veneerd and veneer only): 'make' builds it"
fi
if [ -n "${DISPLAY:-}" ] && [ -x "$bin/veneer-viewer" ]; then
  step "opening veneer-viewer on the simulated rig (close the window to end the demo)"
  "$bin/veneer-viewer" --rig "127.0.0.1:$port" --token-file "$store/token" --fingerprint "$fingerprint" \
    --dst "$out/destination" --src "$out/source" || true
fi
step "done: pictures in $out"
