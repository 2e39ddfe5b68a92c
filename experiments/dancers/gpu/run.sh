#!/bin/bash
# What trained the dancers benchmark on a lent H100 on 2026-11-27 (session 27), as one device call: the sweep
# files in SW train side by side (their points with "train.calibrate" = false, h100.toml beside this file),
# then every finished run is calibrated and judged in parallel, and the small files and each run's best-step
# params (not its optimizer state: ~3 MB a run) are packed into $OUT. Deadlines TA/TB/TC are seconds from the
# start. The device needs what ../shared/data held (carried as a tarball, .gpu/data.tar.xz, made with
# `tar cJf .gpu/data.tar.xz -C ../shared data/aclstm/martial data/aclstm/salsa data/asfamc/cmu05 data/asfamc/cmu131`)
# and a tensorboardX wheel in .whl/ (the device's own jax/flax/optax/orbax serve: do not carry those). That day
# training took 220 s; calibration there was compile-bound and did not finish (fixed since: ~1 min a run
# here), so the runs were calibrated and judged on a CPU. Run from the repository root, e.g.
#   SW="experiments/dancers/gpu/h100.toml:5" bash experiments/dancers/gpu/run.sh
set -u
S=$(date +%s); el() { echo $(( $(date +%s) - S )); }
export PYTHONUNBUFFERED=1 XLA_PYTHON_CLIENT_PREALLOCATE=false
TA=${TA:-230}; TB=${TB:-440}; TC=${TC:-535}; STEPS=${STEPS:-2000}; FR=${FR:-10000}
SW=${SW:-"experiments/dancers/gpu/h100.toml:5"}; PY=${PY:-python3}; CAL=${CAL:-}
mkdir -p /tmp/gl
if [ -z "${LOCAL:-}" ]; then
  mkdir -p ../shared && tar xJf .gpu/data.tar.xz -C ../shared || exit 3
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/tensorboardx*.whl || exit 4
  export PYTHONPATH=/tmp/site:$PWD
  nvidia-smi --query-gpu=utilization.gpu,memory.used --format=csv,noheader -l 20 >/tmp/gl/smi.log 2>&1 &
fi
mkdir -p /tmp/gl
$PY -c "import jax, flax, optax, orbax.checkpoint as o; print(jax.__version__, flax.__version__, optax.__version__, jax.devices())"
echo "[$(el)] train"
pids=()
for spec in $SW; do
  f=${spec%:*}; n=${spec##*:}
  for ((i = 0; i < n; i++)); do
    timeout -s TERM $((TA - $(el))) $PY -m chorjax.cli sweep "$f" --shard "$i/$n" >"/tmp/gl/train-$(basename $f .toml)-$i.log" 2>&1 &
    pids+=($!)
  done
done
wait "${pids[@]}"
ls -d runs/*/*/checkpoints/$STEPS 2>/dev/null | sed "s#/checkpoints/$STEPS##" >/tmp/gl/done
echo "[$(el)] trained: $(wc -l </tmp/gl/done)"
export S PY CAL FR
xargs -a /tmp/gl/done -P 24 -I{} sh -c 'timeout -s TERM $(('$TB' - $(date +%s) + $S)) $PY -m chorjax.cli calibrate {} $CAL >/tmp/gl/cal-$(echo {} | tr / _).log 2>&1'
ls runs/*/*/calibration.json 2>/dev/null | sed 's#/calibration.json##' >/tmp/gl/cal
echo "[$(el)] calibrated: $(wc -l </tmp/gl/cal)"
xargs -a /tmp/gl/cal -P 24 -I{} sh -c 'timeout -s TERM $(('$TC' - $(date +%s) + $S)) $PY -m chorjax.cli eval {} --data held-out --frames $FR --num 1 --seeds 0 1 2 3 >/tmp/gl/eval-$(echo {} | tr / _).log 2>&1'
echo "[$(el)] evaluated: $(ls runs/*/*/eval/metrics.json 2>/dev/null | wc -l)"
$PY experiments/dancers/gpu/pack.py "$OUT"
echo "[$(el)] packed"; ls -la "$OUT"
