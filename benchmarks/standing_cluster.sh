#!/usr/bin/env bash
# The end-to-end sweep on a Dask cluster that stays up between sweeps (README: "Sweeps
# on a cluster"), here all on this host: a scheduler, WORKERS precompute workers and
# one evaluation worker per GPU. Three sweeps of CONFIG, each into a new output folder:
#   first  - empty precompute cache, nothing compiled;
#   again  - the same scenes: precompute cache warm, the program in the worker's memory;
#   again2 - once more.
# Prints each run's wall time (the whole command) and its JSON summary. Extra options
# for every `dask worker` in $WORKER_OPTIONS (e.g. "--preload sweeps.distributed.worker_setup").
#   bash benchmarks/standing_cluster.sh [CONFIG] [WORKERS]
set -euo pipefail
config=${1:-benchmarks/e2e_10k.toml}
workers=${2:-16}
tmp=$(mktemp -d)
export SHACC_COMPILE_CACHE=$tmp/compiled
addr=tcp://127.0.0.1:8786
python3 -m dask scheduler --host 127.0.0.1 --port 8786 --no-dashboard > "$tmp/scheduler.log" 2>&1 &
trap 'kill $(jobs -p) 2>/dev/null; wait; rm -rf "$tmp"' EXIT
python3 -m dask worker $addr --nworkers "$workers" --nthreads 1 --resources precompute=1 \
  ${WORKER_OPTIONS:-} \
  > "$tmp/precompute.log" 2>&1 &
gpus=$(nvidia-smi -L 2>/dev/null | grep -c '^GPU' || true)
for ((g = 0; g < ${gpus:-0}; g++)); do
  CUDA_VISIBLE_DEVICES=$g python3 -m dask worker $addr --nthreads 1 --resources evaluate=1 \
    ${WORKER_OPTIONS:-} \
    > "$tmp/evaluate-$g.log" 2>&1 &
done
python3 -c "from distributed import Client; Client('$addr', timeout=60).wait_for_workers($workers + ${gpus:-0}, timeout=120)"
for run in first again again2; do
  TIMEFORMAT="$run: wall %R s"
  time python3 -m sweeps sweep "$config" --out "$tmp/out-$run" --scheduler $addr \
    --cache "$tmp/precompute" --quiet > "$tmp/$run.json"
  cat "$tmp/$run.json"
done
