#!/bin/bash
# acLSTM at its published size (configs/aclstm.toml) trained for a fixed wall-clock time on one GPU, then
# scored on the dataset's held-out takes like any run of the dancers benchmark. What gave results/gpu/ (an
# NVIDIA H200, 2026-11-26, its image's jax 0.11.2 / flax 0.12.10 with the CUDA plugin):
#   DATA=/path/to/aclstm/salsa VAL='["12","27","14","29"]' experiments/aclstm/gpu.sh 360 OUT_DIR
#   DATA=/path/to/aclstm/martial VAL='["08","10"]' experiments/aclstm/gpu.sh 265 OUT_DIR
# The first argument is the training's wall-clock in seconds (compilation included): SIGTERM then ends it
# with a checkpoint of the step it reached, which eval scores. Needs chorjax importable (PYTHONPATH=. works).
set -u
TRAIN_S=$1; OUT=$2; PY=${PY:-python3}
DS=$(basename "$DATA"); RUN=${RUN:-runs/aclstm_gpu/aclstm-$DS-seed=0}
mkdir -p "$OUT"
export PYTHONUNBUFFERED=1
t0=$(date +%s)
timeout -s TERM "$TRAIN_S" $PY -m chorjax.cli train configs/aclstm.toml "data.dataset=$DATA" data.resample_fps=30 \
  "data.val_takes=$VAL" train.log_every=100 --workdir "$RUN" 2>&1 | tee "$OUT/train.log"
rc=${PIPESTATUS[0]}
echo "train rc $rc after $(($(date +%s) - t0)) s"
[ "$rc" -eq 0 ] || [ "$rc" -eq 124 ] || exit 5 # 124: stopped by the timeout, checkpoint saved
$PY -m chorjax.cli eval "$RUN" --data held-out --frames 10000 --num 1 --seeds 0 1 2 3 2>&1 | tee "$OUT/eval.log"
$PY -m chorjax.cli render "$RUN/eval/sample.npz" --strip --force -o "$OUT/strip_${DS}_gpu.png"
cp "$RUN/eval/metrics.json" "$RUN/config.json" "$OUT/" && cp "$RUN/metrics.jsonl" "$OUT/train_metrics.jsonl"
