# make buildtime: how long the build takes cold, so the next change that slows
# it is seen (issue 41). Configures a fresh build folder (default
# build-time/), builds with the compiler cache off (CI and a newcomer's first
# build are cold) first what `make demo` builds, configured as `make demo`
# configures (no viewer, no tests), then, configured as `make test` does, the
# rest of what `make test` builds. Prints for each the build steps, the wall
# time, the CPU time (user + sys) and the CPU time over the cores (what a
# quiet machine would take, less the waits for the last steps), the machine's
# load beside it (a wall time taken while something else builds says little;
# the CPU time much less disturbed), and the slowest translation units and
# links from .ninja_log.
#   tools/buildtime.sh [build folder] [jobs] [how many units to list]
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
dir="${1:-$root/build-time}"
jobs="${2:-$(nproc)}"
top="${3:-10}"
case "$dir" in /*) ;; *) dir="$root/$dir" ;; esac

load() { cut -d' ' -f1-3 /proc/loadavg; }
now() { date +%s.%N; }
secs() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.0f", b - a }'; }
# cpu VAR: VAR = user + sys seconds of this shell's finished children so far
# (bash's times, run in this shell: in $(...) it would count a subshell's)
cpu() { times > "$dir/buildtime-times"
  printf -v "$1" '%s' "$(awk 'NR == 2 { for (i = 1; i <= 2; i++) { split($i, t, "m"); s += t[1] * 60 + t[2] } printf "%.1f", s }' \
    "$dir/buildtime-times")"; }
cores=$(nproc); [ "$jobs" -lt "$cores" ] && cores=$jobs
# row NAME STEPS T0 T1 C0 C1 LOAD
row() {
  awk -v n="$1" -v st="$2" -v t0="$3" -v t1="$4" -v c0="$5" -v c1="$6" -v l="$7" -v k="$cores" \
    'BEGIN { printf "| %s | %s | %.0f | %.0f | %.0f | %s |\n", n, st, t1 - t0, c1 - c0, (c1 - c0) / k, l }'
}

rm -rf "$dir"; mkdir -p "$dir"
echo "buildtime: cold build in $dir, $jobs jobs, $(nproc) cores; load before: $(load)"
t0=$(now); cpu c0
CCACHE_DISABLE=1 cmake -S "$root" -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=Release -DVENEER_BUILD_APP=OFF \
  -DVENEER_BUILD_TESTS=OFF > "$dir/buildtime-configure.log" 2>&1 || { cat "$dir/buildtime-configure.log"; exit 1; }
t1=$(now); cpu c1
CCACHE_DISABLE=1 cmake --build "$dir" -j "$jobs" --target veneerd veneer > "$dir/buildtime-demo.log" 2>&1 ||
  { tail -30 "$dir/buildtime-demo.log"; exit 1; }
t2=$(now); cpu c2
demo_load=$(load)
demo_steps=$(awk 'NR > 1' "$dir/.ninja_log" | wc -l)
CCACHE_DISABLE=1 cmake -S "$root" -B "$dir" -DVENEER_BUILD_APP=ON -DVENEER_BUILD_TESTS=ON \
  >> "$dir/buildtime-configure.log" 2>&1 || { cat "$dir/buildtime-configure.log"; exit 1; }
CCACHE_DISABLE=1 cmake --build "$dir" -j "$jobs" > "$dir/buildtime-test.log" 2>&1 ||
  { tail -30 "$dir/buildtime-test.log"; exit 1; }
t3=$(now); cpu c3
test_load=$(load)

steps=$(awk 'NR > 1' "$dir/.ninja_log" | wc -l)
printf '\n| step | build steps | wall s | CPU s (user+sys) | CPU s / %s cores | load (1, 5, 15 min) after |\n' "$cores"
printf '|---|---|---|---|---|---|\n'
row "configure (as make demo does)" "" "$t0" "$t1" "$c0" "$c1" ""
row "make demo's targets (veneerd, veneer)" "$demo_steps" "$t1" "$t2" "$c1" "$c2" "$demo_load"
row "reconfigure and the rest of make test's build" "$((steps - demo_steps))" "$t2" "$t3" "$c2" "$c3" "$test_load"
row "make test's build in all" "$steps" "$t0" "$t3" "$c0" "$c3" ""

# .ninja_log: start ms, end ms, mtime, output, hash (one line per output)
printf '\nslowest %s steps (wall s, output):\n' "$top"
awk 'NR > 1 { printf "%7.1f  %s\n", ($2 - $1) / 1000, $4 }' "$dir/.ninja_log" | sort -rn | head -n "$top"
awk 'NR > 1 { d = ($2 - $1) / 1000; all += d; if ($4 ~ /\.o$/) { c += d; if ($4 ~ /^tests\//) t += d } else l += d }
     END { printf "\nsteps'"'"' wall s summed: compiles %.0f (tests %.0f), links and other steps %.0f, all %.0f\n", c, t, l, all }' \
  "$dir/.ninja_log"
