#!/usr/bin/env bash
# Scaling of the end-to-end sweep over precompute workers (the performance targets (reference/index), issue 14):
# the e2e config at COUNT scenes, once per worker count, each from an empty precompute
# cache with the compiled programs kept (a first small sweep of the same shapes fills
# the compilation cache, so every timed run loads the same programs).
#   bash benchmarks/scaling.sh COUNT "W1 W2 ..."
set -euo pipefail
count=${1:-100000}
workers=${2:-"16 32"}
tmp=$(mktemp -d)
export SHACC_COMPILE_CACHE=$tmp/compiled
sed "s/^count = .*/count = 1000/" benchmarks/e2e_10k.toml > "$tmp/compile.toml"
sed "s/^count = .*/count = $count/" benchmarks/e2e_10k.toml > "$tmp/sweep.toml"
python3 -m sweeps sweep "$tmp/compile.toml" --out "$tmp/out-compile" \
  --cache "$tmp/precompute-compile" --quiet > /dev/null
for w in $workers; do
  TIMEFORMAT="workers $w: wall %R s"
  time python3 -m sweeps sweep "$tmp/sweep.toml" --out "$tmp/out-$w" --workers "$w" \
    --cache "$tmp/precompute-$w" --quiet > "$tmp/$w.json"
  cat "$tmp/$w.json"
  rm -rf "$tmp/out-$w" "$tmp/precompute-$w"
done
rm -rf "$tmp"
