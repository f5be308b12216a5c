#!/usr/bin/env bash
# Runs each libFuzzer target (build-fuzz/fuzz/fuzz_*) for N seconds from its
# seed corpus (tests/fuzz/corpus/<name>/). Crashes land in fuzz-out/<name>/.
set -euo pipefail
build="${1:-build-fuzz}"; seconds="${2:-30}"
root="$(cd "$(dirname "$0")/.." && pwd)"
shopt -s nullglob
status=0
for prog in "$build"/fuzz/fuzz_*; do
  name="$(basename "$prog")"; name="${name#fuzz_}"
  corpus="$root/tests/fuzz/corpus/$name"; work="$root/fuzz-out/$name"
  mkdir -p "$work/corpus"
  [ -d "$corpus" ] && cp -n "$corpus"/* "$work/corpus/" 2>/dev/null || true
  echo "=== fuzz $name for ${seconds}s ==="
  if ! "$prog" -max_total_time="$seconds" -artifact_prefix="$work/" -print_final_stats=1 "$work/corpus" ; then
    echo "fuzz $name: FOUND A CRASH (see $work)"; status=1
  fi
done
exit $status
