#!/usr/bin/env bash
# The test run leaves $HOME as it found it (issue 49). Every test runs with its
# XDG folders in the build's test-home/ (CMakeLists.txt, VENEER_TEST_ENVIRONMENT);
# this script checks that nothing reached the user's own:
#   home_guard.sh snapshot STATE TEST_HOME [SKIP...]  empties TEST_HOME (the run's
#       XDG folders start fresh), writes the listing of $HOME to STATE
#   home_guard.sh compare STATE [SKIP...]             lists $HOME again; fails naming
#       every path added, removed or changed since STATE
# The listing: the names directly in $HOME, and every file and folder (type,
# size, modification time) under the folders where programs keep settings,
# caches and data: ~/.config, ~/.cache, ~/.local. Not listed: SKIP paths (the
# build and source trees, when they sit there), the compiler cache (builds run
# beside tests), and the paths in $VENEER_HOME_GUARD_IGNORE (':'-separated,
# relative to $HOME: what other programs of the machine write while the tests
# run, e.g. a browser's cache).
set -euo pipefail
home="${HOME:?HOME is not set}"
home="$(cd "$home" && pwd -P)"

listing() {
  local prune=(-path "$home/.cache/ccache") p
  [ -n "${CCACHE_DIR:-}" ] && prune+=(-o -path "${CCACHE_DIR%/}")
  for p in "$@"; do [ -n "$p" ] && prune+=(-o -path "$(cd "$p" 2>/dev/null && pwd -P || echo "$p")"); done
  local IFS=:
  for p in ${VENEER_HOME_GUARD_IGNORE:-}; do [ -n "$p" ] && prune+=(-o -path "$home/${p%/}"); done
  unset IFS
  find "$home" -mindepth 1 -maxdepth 1 \( "${prune[@]}" \) -prune -o -printf 'in ~: %P\n'
  for p in .config .cache .local; do
    [ -d "$home/$p" ] || continue
    find "$home/$p" \( "${prune[@]}" \) -prune -o -printf '%y %s %T@ ~/%P\n' | sed "s| ~/| ~/$p/|"
  done
}

case "${1:-}" in
  snapshot)
    state="$2" test_home="$3"; shift 3
    rm -rf "$test_home"; mkdir -p "$test_home"
    mkdir -p "$(dirname "$state")"
    listing "$@" | sort > "$state"
    echo "home: $(wc -l < "$state") entries of $home listed; the tests' XDG folders in $test_home"
    ;;
  compare)
    state="$2"; shift 2
    [ -f "$state" ] || { echo "home: no listing at $state (the snapshot test did not run)"; exit 1; }
    now="$(mktemp)"; trap 'rm -f "$now"' EXIT
    listing "$@" | sort > "$now"
    if ! cmp -s "$state" "$now"; then
      echo "home: the test run changed $home (- before, + after; type size mtime path):"
      diff "$state" "$now" | grep '^[<>]' | sed -e 's/^</-/' -e 's/^>/+/' | head -50
      echo "home: a test wrote outside its XDG folders (test-home/); if another program of this"
      echo "machine wrote there, name its folder in VENEER_HOME_GUARD_IGNORE (relative to \$HOME)"
      exit 1
    fi
    echo "home: $home unchanged ($(wc -l < "$now") entries)"
    ;;
  *) echo "usage: home_guard.sh snapshot STATE TEST_HOME [SKIP...] | compare STATE [SKIP...]" >&2; exit 2 ;;
esac
