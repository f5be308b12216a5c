#!/usr/bin/env bash
# Every shell script under tools/ and the packages' maintainer scripts parse
# (bash -n / sh -n), and each package list names packages one per line.
set -euo pipefail
src="$1"; n=0
while IFS= read -r f; do
  case "$(head -1 "$f")" in
    *bash*) bash -n "$f" ;;
    *sh*)   sh -n "$f" ;;
    *) continue ;;
  esac
  n=$((n + 1))
done < <(find "$src/tools" -type f \( -name '*.sh' -o -name 'install-*' -o -name '*.postinst' -o -name '*.prerm' -o -name '*.postrm' \) | sort)
[ "$n" -ge 8 ] || { echo "only $n scripts found under tools/"; exit 1; }
for list in "$src"/tools/debian-packages*.txt; do
  if sed 's/#.*//' "$list" | grep -vE '^[[:space:]]*$' | grep -vqE '^[a-z0-9][a-z0-9.+-]+(:[a-z0-9]+)?$'; then
    echo "$list: a line is not one package name:"; sed 's/#.*//' "$list" | grep -vE '^[[:space:]]*$' | grep -vE '^[a-z0-9][a-z0-9.+-]+(:[a-z0-9]+)?$'
    exit 1
  fi
done
echo "$n scripts parse; package lists well formed"
