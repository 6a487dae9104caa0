#!/usr/bin/env bash
# Checks the test-data check (scripts/test-data.sh), so that it can fail:
#   1. `verify` passes on the data the tests use ($LEVELMAP_DATA, else ../shared/data);
#   2. on a copy with one byte of a listed file changed and another listed file gone, it
#      fails and names exactly those two;
#   3. every listed file has a download origin, and tests/README.md's table lists exactly the
#      files of tests/data.sha256 (the table is kept by hand).
# Fast (well under a second on 2 cores): .ci/run calls it before the cargo steps.
set -euo pipefail
cd "$(dirname "$0")/.."
data=${LEVELMAP_DATA:-../shared/data}
list=tests/data.sha256
fail() {
  echo "test-data-selftest: FAIL: $*" >&2
  exit 1
}
paths() { grep -v '^#' "$list" | awk 'NF == 2 { print $2 }'; }

# 1. The real data.
scripts/test-data.sh verify "$data" || fail "verify fails on $data (fetch it: scripts/test-data.sh fetch)"

# 2. A copy (links to the real files) with one file corrupted and one missing.
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
while read -r path; do
  mkdir -p "$tmp/$(dirname "$path")"
  ln -s "$(cd "$data" && pwd)/$path" "$tmp/$path"
done < <(paths)
# The smallest listed file gets a changed byte in its middle; the largest goes missing.
sized=$(while read -r path; do echo "$(stat -Lc %s "$data/$path") $path"; done < <(paths) | sort -n)
small=$(head -1 <<<"$sized" | cut -d' ' -f2)
large=$(tail -1 <<<"$sized" | cut -d' ' -f2)
rm "$tmp/$small" "$tmp/$large"
cp "$data/$small" "$tmp/$small"
chmod u+w "$tmp/$small" # the shared copies are read-only
at=$(($(stat -c %s "$tmp/$small") / 2))
old=$(dd if="$tmp/$small" bs=1 skip="$at" count=1 2>/dev/null)
new=X
[ "$old" != X ] || new=Y
printf %s "$new" | dd of="$tmp/$small" bs=1 seek="$at" conv=notrunc 2>/dev/null
cmp -s "$data/$small" "$tmp/$small" && fail "could not corrupt $small"

set +e
out=$(scripts/test-data.sh verify "$tmp" 2>&1)
rc=$?
set -e
[ "$rc" -ne 0 ] || fail "verify passed on a corrupted copy: $out"
grep -qx "mismatch: $small (.*)" <<<"$out" || fail "verify did not name the corrupted $small: $out"
grep -qx "missing: $large" <<<"$out" || fail "verify did not name the missing $large: $out"
named=$(grep -c '^\(mismatch\|missing\): ' <<<"$out" || true)
[ "$named" -eq 2 ] || fail "verify named $named files, not 2: $out"

# 3. Origins, and the README's table.
# (mawk has no {40}: the commit, the URL's sixth /-field, is checked by its length.)
origins=$(awk '/^# url: https:\/\/raw\.githubusercontent\.com\// {
    split($3, f, "/"); u = f[6] ~ /^[0-9a-f]+$/ && length(f[6]) == 40 && f[7] != ""; next }
  /^#/ || NF == 0 { next } { if (!u) print $2; u = 0 }' "$list")
[ -z "$origins" ] || fail "no pinned raw GitHub '# url:' line for: $origins"
readme=$(sed -n 's/^| `\([^`]*\)` |.*/\1/p' tests/README.md | sort)
[ "$readme" = "$(paths | sort)" ] ||
  fail "tests/README.md's table and $list list different files: $(diff <(echo "$readme") <(paths | sort) | grep '^[<>]' | tr '\n' ' ')"

echo "test-data-selftest: ok ($(paths | wc -l) files; a corrupted $small and a missing $large were named)"
