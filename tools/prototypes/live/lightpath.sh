#!/usr/bin/env bash
# Issue 47's table: a live sequence of SOURCE under one lamp moving on PATH,
# repainted onto the bull (the demo pair's destination) by the default live
# look and by `--look copy` through the exact-nearest-normal map, both scored
# by shared/tools/lightpath.py against the truth frames (the bull in SOURCE's
# material under the same lamp).
#
#   lightpath.sh [SOURCE [PATH [FRAMES [SIZE]]]]
#     SOURCE  the source scene (default orange); PATH as `veneer simulate
#             --light-path` takes it (default spiral; issue 47 also:
#             circle,radius=0.47,height=1 and arc,radius=0.9,height=0.3)
#     FRAMES  default 24; SIZE default 1024x680
# Env: VENEER (default build/bin/veneer of this checkout); WORK (scratch,
#      default a temp dir; kept: the sets and transfers are reused when
#      REUSE=1 and they exist); LIVE_ARGS (extra args of the live repaint).
# Prints lightpath.py's table and writes WORK/score.json.
set -euo pipefail
here="$(cd "$(dirname "$0")/../../.." && pwd)"
src="${1:-orange}"; path="${2:-spiral}"; frames="${3:-24}"; size="${4:-1024x680}"
veneer="${VENEER:-$here/build/bin/veneer}"
work="${WORK:-$(mktemp -d)}"
tool="$here/../shared/tools/lightpath.py"
mkdir -p "$work"; log="$work/log"; : > "$log"
common=(--size "$size" --overwrite)
t() { "$@" >> "$log" 2>&1 || { echo "failed: $* (see $log)" >&2; tail -5 "$log" >&2; exit 1; }; }
have() { [ "${REUSE:-0}" = 1 ] && [ -e "$1" ]; }
echo "lightpath: bull <- $src, $path, $frames frames, $size, in $work" >&2
have "$work/dst/set.json" || t "$veneer" simulate --scene bull --role destination --out "$work/dst" "${common[@]}"
have "$work/src/set.json" || t "$veneer" simulate --scene "$src" --role source --out "$work/src" "${common[@]}"
have "$work/truthset/set.json" || t "$veneer" simulate --scene bull --material "$src" --role destination --noise 0 --out "$work/truthset" "${common[@]}"
have "$work/seq/light_path.json" || t "$veneer" simulate --scene bull --material "$src" --light-path "$path" --frames "$frames" --out "$work/seq" "${common[@]}"
pair=(--dst "$work/dst" --src "$work/src")
have "$work/t_default/metrics.json" || t "$veneer" transfer "${pair[@]}" --out "$work/t_default" --no-cache
have "$work/t_linear/metrics.json" || t "$veneer" transfer "${pair[@]}" --out "$work/t_linear" --method linear --look copy --no-cache
rm -rf "$work/live" "$work/copy"
t "$veneer" repaint "${pair[@]}" --map "$work/t_default" --video "$work/seq" --out "$work/live" ${LIVE_ARGS:-}
t "$veneer" repaint "${pair[@]}" --map "$work/t_linear" --video "$work/seq" --out "$work/copy" --look copy
/usr/bin/python3 "$tool" score "$work/seq" "$work/truthset" "$work/live" "$work/t_default" "$work/copy" "$work/t_linear" > "$work/score.json"
/usr/bin/python3 "$tool" table "$work/score.json"
