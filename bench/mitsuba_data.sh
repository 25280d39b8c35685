#!/bin/bash
# Tries every scene of Mitsuba's mitsuba-data (not the include/ and fragments/ files) with one
# pass and prints OK or the first line of the error, then the count: the figure the README
# and issue notes quote as "N of 148 load and render".
#
#   bench/mitsuba_data.sh DATA_DIR [COORDINATOR]
#
# DATA_DIR is a checkout of mitsuba-renderer/mitsuba-data (git-lfs files fetched).
set -u
data=${1:?usage: bench/mitsuba_data.sh DATA_DIR [COORDINATOR]}
bin=$(realpath "${2:-target/release/coordinator}")
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
cd "$data"
ok=0
total=0
while read -r s; do
    total=$((total + 1))
    if timeout 120 "$bin" render "$s" --spp 1 --out "$out/image.exr" >"$out/log" 2>&1; then
        ok=$((ok + 1))
        echo "OK   $s"
    else
        echo "FAIL $s :: $(grep -v '^\s*$' "$out/log" | grep -iv warn | tail -1 | cut -c1-200)"
    fi
done < <(find . -name '*.xml' -not -path '*/include/*' -not -path '*/fragments/*' | sed 's|^\./||' | sort)
echo "$ok of $total scenes load and render"
