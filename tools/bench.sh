#!/usr/bin/env bash
# Runs every benchmark program (build/bench/bench_*) in name order and prints
# its tables. Benchmarks measure; they never fail on a number.
set -euo pipefail
build="${1:-build}"
shopt -s nullglob
progs=("$build"/bench/bench_*)
if [ ${#progs[@]} -eq 0 ]; then echo "bench: no benchmark programs in $build/bench" >&2; exit 1; fi
for prog in "${progs[@]}"; do
  echo
  echo "=== $(basename "$prog") ==="
  "$prog"
done
