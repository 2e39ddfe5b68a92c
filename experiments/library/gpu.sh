#!/bin/bash
# configs/library.toml on one GPU (BENCHMARKS.md measured the recipe of then, sweep.toml's white): read cold
# (the cache empty, one process per core), read warm (the cache filled), the training's steps/s and time to the
# kept checkpoint, and three seeds as one vectorized program.
# A device call carries at most 64 MiB, so the library travels as a subset made here, e.g.
#   cd DIR_WITH_UNPACKED && ls bandai-motion/dataset-1_*.bvh bandai-motion/dataset-2_*_00[1-8].bvh \
#     bandai-motion/*.md bandai-motion/*.txt | tar cf - -T - | xz -6 > REPO/.gpu/bandai-subset.tar.xz
# (734 takes, 26 MB) with a tensorboardX wheel in .whl/ (the device's own jax/flax/optax/orbax serve). Run
# from the repository root; OUT (a folder) gets the logs. LOCAL=1: no unpacking or installing (a CPU check,
# with DATA=the unpacked folder and STEPS=a few).
set -u
S=$(date +%s); el() { echo $(( $(date +%s) - S )); }
export PYTHONUNBUFFERED=1 XLA_PYTHON_CLIENT_PREALLOCATE=false
PY=${PY:-python3}; OUT=${OUT:-/tmp/gl}; DATA=${DATA:-/tmp/lib/bandai-motion}; EPOCHS=${EPOCHS:-60}
mkdir -p "$OUT"
if [ -z "${LOCAL:-}" ]; then
  mkdir -p /tmp/lib && tar xJf .gpu/bandai-subset.tar.xz -C /tmp/lib || exit 3
  $PY -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/tensorboardx*.whl || exit 4
  export PYTHONPATH=/tmp/site:$PWD
  nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
fi
$PY -c "import jax, flax, optax, orbax.checkpoint as o; print(jax.__version__, flax.__version__, optax.__version__, jax.devices())"
train() {  # NAME TIMEOUT_S KEY=VALUE...
  local name=$1 limit=$2; shift 2
  echo "[$(el)] $name"
  local t0 timer=""; t0=$(date +%s)
  [ -x /usr/bin/time ] && timer="/usr/bin/time -v"
  timeout -s TERM "$limit" $timer $PY -m chorjax.cli train configs/library.toml "data.dataset=$DATA" \
    data.cache=/tmp/lib/cache "train.epochs=$EPOCHS" train.log_every=250 log.progress=lines --force \
    --workdir "runs/library_gpu/$name" "$@" > "$OUT/$name.log" 2>&1
  echo "$name rc $? wall $(( $(date +%s) - t0 )) s"
  grep -E "^(step|train\.epochs|trained|kept|ended|stopp|calibrat)|Maximum resident|Elapsed" "$OUT/$name.log" | tail -14
}
train cold 240 train.calibrate=false
train warm 240 train.calibrate=false
train calibrated 200
train seeds 200 "train.seed=[0,1,2]" train.calibrate=false train.patience=0
echo "[$(el)] done"
