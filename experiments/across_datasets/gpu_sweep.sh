#!/bin/bash
# Sweep points sharded over one lent GPU: what made the H100 rows of table.md (2026-11-26). From the
# repository root, with the datasets at ../shared/data and chorjax importable (PYTHONPATH=. works):
#   experiments/across_datasets/gpu_sweep.sh SECONDS SWEEP.toml:SHARDS [SWEEP.toml:SHARDS ...] OUT_DIR
# runs SHARDS `chorjax sweep SWEEP.toml --shard I/SHARDS` processes per sweep side by side for SECONDS
# (SIGTERM then saves each training's checkpoint; the same command resumes), then packs the small files of
# every evaluated point (config, calibration, metrics log, eval metrics) into OUT_DIR/small.tgz, seed 0's
# eval samples (for the filmstrips) into OUT_DIR/samples.tgz and the logs into OUT_DIR/logs.tgz. The H100
# run: sweep files holding the points not yet run here (the martial, cmu05 and cmu131 candidates of
# rnn_types/dancers.toml, 6 shards; cmu05 and cmu131 of mdn_vs_mse/dancers.toml, 2; families/dancers.toml,
# 3). Lesson: 11 processes on one GPU trained at 5-40 steps/s each and calibration (CPU-bound) dominated;
# 6 at a time trained at 60-300 steps/s.
set -u
T=$1; shift; OUT=${*: -1}; set -- "${@:1:$#-1}"
export PYTHONUNBUFFERED=1 XLA_PYTHON_CLIENT_PREALLOCATE=false
mkdir -p "$OUT" /tmp/sweep_logs
for spec in "$@"; do
  file=${spec%:*}; n=${spec##*:}
  for ((i = 0; i < n; i++)); do
    timeout -s TERM "$T" python3 -m chorjax.cli sweep "$file" --shard "$i/$n" >"/tmp/sweep_logs/$(basename "$file" .toml)-$i-of-$n.log" 2>&1 &
  done
done
wait
find runs -path '*/eval/metrics.json' | sed 's#/eval/metrics.json##' | sort >/tmp/sweep_done
: >/tmp/sweep_small; : >/tmp/sweep_npz
while read -r d; do
  for f in config.json calibration.json metrics.jsonl eval/metrics.json; do [ -f "$d/$f" ] && echo "$d/$f" >>/tmp/sweep_small; done
  case "$d" in *seed=0) echo "$d/eval/sample.npz" >>/tmp/sweep_npz ;; esac
done </tmp/sweep_done
tar czf "$OUT/small.tgz" -T /tmp/sweep_small && tar czf "$OUT/samples.tgz" -T /tmp/sweep_npz && tar czf "$OUT/logs.tgz" -C /tmp sweep_logs
echo "$(wc -l </tmp/sweep_done) points evaluated"
