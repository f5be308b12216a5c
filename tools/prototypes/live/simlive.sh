#!/usr/bin/env bash
# Issue 40's "what must show" on the simulated demo pair: the bull
# (destination) <- the orange (source), a live sequence of the orange under one
# lamp moving off the captured lamps (`veneer simulate --light-path`), scored
# frame by frame against the truth frames (the bull in the orange's material
# under the same lamp) by `veneer eval --live`:
#   live:  veneer transfer (default map, default shaded look), then
#          veneer repaint --video (default: the shaded live look)
#   copy:  veneer transfer --method linear --look copy (the exact-nearest-normal
#          map), then veneer repaint --look copy through it
# texture_corr is look.py's (the repainted frame's high-pass against the
# SOURCE's median photo warped through the map: --map/--src), the light is the
# repaint's estimate (report.json) against the path's lamp (light_path.json).
# Prints one row per frame (live, copy, ratio, texture_corr, light angle), the
# means and the goals: ratio of means <= 0.7, texture_corr >= 0.6 on every
# frame, median light angle <= 3 deg.
#
#   simlive.sh [SIZE [FRAMES [PATH]]]
#     SIZE    WxH of the sets and the sequence (default 1024x680)
#     FRAMES  frames of the sequence (default 24)
#     PATH    the light path (default spiral: 3.6-48.4 deg off the axis, never
#             nearer than 9.8 deg to a captured lamp)
# Env: VENEER (the veneer binary, default build/bin/veneer of this checkout),
#      SCALE (the objects' --scale, default 1 as the simulated rig frames them),
#      WORK (scratch folder, default a temp dir; kept).
set -euo pipefail
here="$(cd "$(dirname "$0")/../../.." && pwd)"
size="${1:-1024x680}"
frames="${2:-24}"
path="${3:-spiral}"
scale="${SCALE:-1}"
veneer="${VENEER:-$here/build/bin/veneer}"
py="${PYTHON:-/usr/bin/python3}"
work="${WORK:-$(mktemp -d)}"
[ -x "$veneer" ] || { echo "no veneer at $veneer (build it: cmake --build build --target veneer)" >&2; exit 1; }
mkdir -p "$work"
log="$work/log"; : > "$log"
common=(--size "$size" --scale "$scale" --overwrite)
t() { local s=$SECONDS; "$@" >> "$log" 2>&1 || { echo "failed: $* (see $log)" >&2; tail -5 "$log" >&2; exit 1; }; echo "  $(( SECONDS - s )) s: ${*:2:1} ${*:3:1}" >&2; }
echo "simlive: $size, $frames frames, path $path, scale $scale, in $work" >&2
t "$veneer" simulate --scene bull --role destination --out "$work/dst" "${common[@]}"
t "$veneer" simulate --scene orange --role source --out "$work/src" "${common[@]}"
t "$veneer" simulate --scene bull --material orange --light-path "$path" --frames "$frames" --out "$work/seq" "${common[@]}"
pair=(--dst "$work/dst" --src "$work/src")
t "$veneer" transfer "${pair[@]}" --out "$work/t_default" --no-cache
t "$veneer" repaint "${pair[@]}" --map "$work/t_default" --video "$work/seq" --out "$work/live"
t "$veneer" transfer "${pair[@]}" --out "$work/t_linear" --method linear --look copy --no-cache
t "$veneer" repaint "${pair[@]}" --map "$work/t_linear" --video "$work/seq" --out "$work/copy" --look copy
t "$veneer" eval --live "$work/live" --truth "$work/seq" --map "$work/t_default" --src "$work/src"
t "$veneer" eval --live "$work/copy" --truth "$work/seq" --map "$work/t_linear" --src "$work/src"
"$py" - "$work" <<'EOF'
import json, sys
w = sys.argv[1]
live = json.load(open(w + '/live/live_look.json'))
copy = json.load(open(w + '/copy/live_look.json'))
rep = json.load(open(w + '/live/report.json'))
print('%5s %8s %8s %6s %9s %9s %9s %8s %5s' % ('frame', 'live', 'copy', 'ratio', 'tex live', 'tex copy', 'light deg', 'residual', 'expl'))
for i, (a, b) in enumerate(zip(live['frames'], copy['frames'])):
    l = rep['per_frame'][i].get('light', {})
    fmt = lambda v, f: (f % v) if v is not None else '-'
    print('%5d %8.4f %8.4f %6.2f %9s %9s %9s %8s %5s' % (
        i, a['shading_mean'], b['shading_mean'], a['shading_mean'] / max(b['shading_mean'], 1e-12),
        fmt(a['texture_corr'], '%.3f'), fmt(b['texture_corr'], '%.3f'), fmt(a['light_angle_deg'], '%.2f'),
        fmt(l.get('residual'), '%.3f'), l.get('explained', '-')))
lm, cm = live['mean']['shading_mean'], copy['mean']['shading_mean']
ratio = lm / cm
tmin = live['mean']['texture_corr_min']
ang = live['mean']['light_angle_median_deg']
print('%5s %8.4f %8.4f %6.2f %9.3f %9.3f %9s' % ('mean', lm, cm, ratio, live['mean']['texture_corr'],
      copy['mean']['texture_corr'], '%.2f' % ang if ang is not None else '-'))
print('goals: ratio %.3f (<= 0.7: %s), texture_corr min %.3f (>= 0.6: %s), light median %.2f deg, max %.2f (<= 3: %s)' % (
    ratio, 'met' if ratio <= 0.7 else 'MISSED', tmin, 'met' if tmin >= 0.6 else 'MISSED', ang,
    live['mean']['light_angle_max_deg'], 'met' if ang <= 3 else 'MISSED'))
print('coherence of the default map: %s; look setup %.1f s; ms per frame median %.1f' % (
    json.load(open(w + '/t_default/metrics.json')).get('quality', {}).get('coherence', '-'),
    rep.get('look_setup_s', 0), rep['ms_per_frame']['median']))
EOF
