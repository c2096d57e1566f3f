#!/usr/bin/env bash
# The end-to-end sweep three times, each into a new output folder:
#   cold   - empty precompute cache and empty compilation cache (a new machine);
#   empty  - empty precompute cache, the compiled programs kept from the first run;
#   warm   - both caches warm (a later sweep of the same scenes and precompute settings).
# Prints each run's wall time (the whole command) and its JSON summary.
#   bash benchmarks/e2e.sh [CONFIG] [WORKERS]
set -euo pipefail
config=${1:-benchmarks/e2e_10k.toml}
workers=${2:-16}
tmp=$(mktemp -d)
export SHACC_COMPILE_CACHE=$tmp/compiled
for run in cold empty warm; do
  cache=$tmp/precompute-$run
  [ "$run" = warm ] && cache=$tmp/precompute-empty
  TIMEFORMAT="$run: wall %R s"
  time python3 -m sweeps sweep "$config" --out "$tmp/out-$run" --workers "$workers" \
    --cache "$cache" --quiet > "$tmp/$run.json"
  cat "$tmp/$run.json"
done
du -sh "$tmp/out-cold/scenes" "$tmp/out-cold/rollouts"
rm -rf "$tmp"
