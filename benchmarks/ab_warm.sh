#!/usr/bin/env bash
# Warm end-to-end sweeps of two checkouts of the project, alternated on one host (A/B
# pairs): each checkout first runs the sweep once to fill its own caches (precompute and
# compiled programs), then PAIRS times A and B each run it warm into a new folder.
# Prints one line per run: "A|B warm: wall S s".
#   bash benchmarks/ab_warm.sh DIR_A DIR_B [CONFIG] [WORKERS] [PAIRS]
set -euo pipefail
a=$(cd "$1" && pwd)
b=$(cd "$2" && pwd)
config=$(realpath "${3:-benchmarks/e2e_10k.toml}")
workers=${4:-16}
pairs=${5:-4}
tmp=$(mktemp -d)
run() {  # key (A or B), what, dir, out
  local key=$1 what=$2 dir=$3 out=$4
  TIMEFORMAT="$key $what: wall %R s"
  (cd "$dir" && export SHACC_COMPILE_CACHE="$tmp/compiled-$key" \
    PYTHONPATH="$dir${BASE_PYTHONPATH:+:$BASE_PYTHONPATH}" && \
    time python3 -m sweeps sweep "$config" --out "$out" --workers "$workers" \
    --cache "$tmp/precompute-$key" --quiet > "$out.json")
}
run A first "$a" "$tmp/a0"
run B first "$b" "$tmp/b0"
for i in $(seq "$pairs"); do
  run A warm "$a" "$tmp/a$i"
  run B warm "$b" "$tmp/b$i"
done
rm -rf "$tmp"
