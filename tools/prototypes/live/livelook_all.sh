#!/usr/bin/env bash
# Issue 40's acceptance measure over lamps and both directions of a real pair:
# for each lamp K, K is dropped from both sets (livelook.py drop), the source's
# photo under K is the live frame (livelook.py frame), and
#   live:  veneer transfer (default map, default look) on the dropped sets, then
#          veneer repaint --video of the frame through that map (default: the shaded live look)
#   copy:  veneer transfer --method linear --look copy (the exact-nearest-normal map), then
#          veneer repaint --look copy through it
# each scored by livelook.py score. Prints one row per (pair, lamp) and the means.
#
#   livelook_all.sh [DATA_DIR [LAMPS [PAIRS]]]
#     DATA_DIR  folder of DiLiGenT-layout sets (default /work/shared/data/real or $VENEER_REAL)
#     LAMPS     comma list of 0-based lamps (default all of the destination's)
#     PAIRS     comma list of dst:src (default cat:buddha,buddha:cat)
# Env: VENEER (the veneer binary, default build/bin/veneer of this checkout),
#      LIVELOOK (livelook.py, default /work/shared/tools/livelook.py), WORK (scratch folder, default a temp dir).
set -euo pipefail
here="$(cd "$(dirname "$0")/../../.." && pwd)"
data="${1:-${VENEER_REAL:-/work/shared/data/real}}"
pairs="${3:-cat:buddha,buddha:cat}"
veneer="${VENEER:-$here/build/bin/veneer}"
livelook="${LIVELOOK:-/work/shared/tools/livelook.py}"
py="${PYTHON:-/usr/bin/python3}"
work="${WORK:-$(mktemp -d)}"
[ -x "$veneer" ] || { echo "no veneer at $veneer (build it: cmake --build build --target veneer)" >&2; exit 1; }
printf '%-16s %4s %8s %8s %7s %9s %8s %6s  %s\n' pair lamp live copy ratio coherence residual expl light
json() { "$py" -c "import json,sys; d=json.load(open(sys.argv[1])); print(eval(sys.argv[2]))" "$@"; }
sum_live=0; sum_copy=0; n=0
for pair in ${pairs//,/ }; do
  dst="${pair%%:*}"; src="${pair##*:}"
  count=$(wc -w < "$data/$dst/filenames.txt")
  lamps="${2:-$(seq -s, 0 $((count - 1)))}"
  for k in ${lamps//,/ }; do
    w="$work/$dst-$src-$k"; mkdir -p "$w"
    "$py" "$livelook" drop "$data/$dst" "$k" "$w/dst"
    "$py" "$livelook" drop "$data/$src" "$k" "$w/src"
    "$py" "$livelook" frame "$data/$src" "$k" "$w/frames"
    "$veneer" transfer --dst "$w/dst" --src "$w/src" --out "$w/t_default" --no-cache > "$w/log" 2>&1
    "$veneer" repaint --src "$w/src" --dst "$w/dst" --map "$w/t_default" --video "$w/frames" --out "$w/live" >> "$w/log" 2>&1
    "$veneer" transfer --dst "$w/dst" --src "$w/src" --out "$w/t_linear" --method linear --look copy --no-cache >> "$w/log" 2>&1
    "$veneer" repaint --src "$w/src" --dst "$w/dst" --map "$w/t_linear" --video "$w/frames" --out "$w/copy" --look copy >> "$w/log" 2>&1
    live=$("$py" "$livelook" score "$w/live" "$w/t_default" "$data/$dst" "$k" | json /dev/stdin "d['shading_mean']")
    copy=$("$py" "$livelook" score "$w/copy" "$w/t_linear" "$data/$dst" "$k" | json /dev/stdin "d['shading_mean']")
    coh=$(json "$w/t_default/metrics.json" "round(d['quality']['coherence'], 3)")
    res=$(json "$w/live/report.json" "round(d['per_frame'][0]['light']['residual'], 3)")
    expl=$(json "$w/live/report.json" "d['per_frame'][0]['light']['explained']")
    dir=$(json "$w/live/report.json" "' '.join('%.3f' % v for v in d['per_frame'][0]['light']['direction'])")
    truth=$(sed -n "$((k + 1))p" "$data/$src/light_directions.txt")
    err=$("$py" -c "import numpy as n,sys; a=n.array(sys.argv[1].split(),float); b=n.array(sys.argv[2].split(),float); print('%.1f' % n.degrees(n.arccos(min(1,a@b/n.linalg.norm(a)/n.linalg.norm(b)))))" "$dir" "$truth")
    printf '%-16s %4s %8.4f %8.4f %7.2f %9s %8s %6s  (%s) %s deg off\n' "$dst<-$src" "$k" "$live" "$copy" \
      "$("$py" -c "print($live / $copy)")" "$coh" "$res" "$expl" "$dir" "$err"
    sum_live=$("$py" -c "print($sum_live + $live)"); sum_copy=$("$py" -c "print($sum_copy + $copy)"); n=$((n + 1))
  done
done
"$py" -c "l=$sum_live/$n; c=$sum_copy/$n; print('mean over %d: live %.4f, copy %.4f, live/copy %.2f' % ($n, l, c, l / c))"
