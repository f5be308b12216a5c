#!/usr/bin/env bash
# make buildtime: how long the build takes cold, so the next change that slows
# it is seen (issue 41). Configures a fresh build folder (default
# build-time/), builds with the compiler cache off (CI and a newcomer's first
# build are cold) first what `make demo` builds, then the rest of what
# `make test` builds, and prints the wall time of each, the machine's load
# beside it (a timing taken while something else builds is worthless), and
# the slowest translation units and links from .ninja_log.
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

rm -rf "$dir"; mkdir -p "$dir"
echo "buildtime: cold build in $dir, $jobs jobs, $(nproc) cores; load before: $(load)"
t0=$(now)
CCACHE_DISABLE=1 cmake -S "$root" -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=Release > "$dir/buildtime-configure.log" 2>&1 ||
  { cat "$dir/buildtime-configure.log"; exit 1; }
t1=$(now)
CCACHE_DISABLE=1 cmake --build "$dir" -j "$jobs" --target veneerd veneer > "$dir/buildtime-demo.log" 2>&1 ||
  { tail -30 "$dir/buildtime-demo.log"; exit 1; }
t2=$(now)
demo_load=$(load)
CCACHE_DISABLE=1 cmake --build "$dir" -j "$jobs" > "$dir/buildtime-test.log" 2>&1 ||
  { tail -30 "$dir/buildtime-test.log"; exit 1; }
t3=$(now)
test_load=$(load)

steps=$(awk 'NR > 1' "$dir/.ninja_log" | wc -l)
printf '\n| step | wall s | load (1, 5, 15 min) after |\n|---|---|---|\n'
printf '| configure | %s | |\n' "$(secs "$t0" "$t1")"
printf "| make demo's targets (veneerd, veneer) | %s | %s |\n" "$(secs "$t1" "$t2")" "$demo_load"
printf "| the rest of make test's build | %s | %s |\n" "$(secs "$t2" "$t3")" "$test_load"
printf "| make test's build in all (%s steps) | %s | |\n" "$steps" "$(secs "$t0" "$t3")"

# .ninja_log: start ms, end ms, mtime, output, hash (one line per output)
printf '\nslowest %s steps (s, output):\n' "$top"
awk 'NR > 1 { printf "%7.1f  %s\n", ($2 - $1) / 1000, $4 }' "$dir/.ninja_log" | sort -rn | head -n "$top"
awk 'NR > 1 { d = ($2 - $1) / 1000; all += d; if ($4 ~ /\.o$/) { c += d; if ($4 ~ /^tests\//) t += d } else l += d }
     END { printf "\nCPU s: compiles %.0f (tests %.0f), links and other steps %.0f, all %.0f\n", c, t, l, all }' \
  "$dir/.ninja_log"
