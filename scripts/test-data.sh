#!/usr/bin/env bash
# The public data the tests and benches read (tests/README.md), from the one list of it,
# tests/data.sha256: each file's path in the data folder, its sha256 and, on the `# url:` line
# above it, where it is downloaded from.
#
#   scripts/test-data.sh fetch  [DEST]   download every listed file into DEST, then verify
#   scripts/test-data.sh verify [DIR]    check every listed file's sha256; exit 1 on any
#                                        mismatch or missing file, naming each
#
# DEST and DIR default to $LEVELMAP_DATA, else ../shared/data beside the repository (where the
# tests look, services/scanio's shared_data).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
list=${LEVELMAP_DATA_LIST:-$root/tests/data.sha256}
default_dir=${LEVELMAP_DATA:-$root/../shared/data}

usage() {
  sed -n '6,8p' "$0" | sed 's/^# \{0,1\}//' >&2
  exit 2
}

sha() { sha256sum "$1" | cut -d' ' -f1; }

# Prints "sha256 path url" for every listed file (url: the `# url:` line before it).
entries() {
  awk '/^# url: / { url = $3; next }
       /^#/ || NF == 0 { next }
       NF != 2 { printf "%s:%d: not a \"sha256  path\" line\n", FILENAME, FNR > "/dev/stderr"; exit 2 }
       { print $1, $2, url; url = "" }' "$list"
}

verify() {
  local dir=$1 n=0 bad=0 want path _url got
  while read -r want path _url; do
    n=$((n + 1))
    if [ ! -f "$dir/$path" ]; then
      echo "missing: $path"
      bad=$((bad + 1))
    else
      got=$(sha "$dir/$path" 2>/dev/null) || got=unreadable
      if [ "$got" != "$want" ]; then
        echo "mismatch: $path (sha256 $got, listed $want)"
        bad=$((bad + 1))
      fi
    fi
  done < <(entries)
  if [ "$bad" -gt 0 ]; then
    echo "verify: $bad of $n files in $dir missing or different" >&2
    return 1
  fi
  echo "verify: all $n files in $dir match $list"
}

fetch() {
  local dest=$1 want path url target failed=0
  while read -r want path url; do
    target=$dest/$path
    # Already there and right: nothing to download (a re-run finishes what a failed one left).
    if [ -f "$target" ] && [ "$(sha "$target")" = "$want" ]; then continue; fi
    if [ -z "$url" ]; then
      echo "fetch: no '# url:' line for $path in $list" >&2
      failed=1
      continue
    fi
    mkdir -p "$(dirname "$target")"
    echo "fetch: $path <- $url"
    # Into a .part first, so an interrupted download never passes for the file.
    if curl -fsSL --retry 3 -o "$target.part" "$url" </dev/null; then
      mv "$target.part" "$target"
    else
      echo "fetch: download failed: $url" >&2
      rm -f "$target.part"
      failed=1
    fi
  done < <(entries)
  # The files are stored as their origins serve them (the .gz and .bz2 logs stay compressed:
  # the tests read them so), so nothing is extracted. verify names anything that differs.
  verify "$dest" || failed=1
  return "$failed"
}

[ $# -ge 1 ] || usage
cmd=$1
shift
[ $# -le 1 ] || usage
case $cmd in
  verify) verify "${1:-$default_dir}" ;;
  fetch) fetch "${1:-$default_dir}" ;;
  *) usage ;;
esac
