"""A/B of ``chorjax.models.fused.dense`` against the plain matmul: train steps alternating in one process.

    python -m benchmarks.dense_ab            # 10 repetitions of each step (about 2 minutes on 2 cores)
    python -m benchmarks.dense_ab --reps 20

The cells' input projections and the heads call ``dense`` through their modules' globals; the plain side
swaps in ``x @ w`` there and compiles its own step (a fresh ``jax.jit``, so no trace is shared). Steps: the
reference LSTM+MDN and LN-LSTM+MSE (3 x 256, batch 50, sequence 100, random data) and the quickstart's
(configs/quickstart.toml, its feature width). Prints the median of each and their ratio.
"""

from __future__ import annotations

import argparse
import functools

import jax
import numpy as np

from benchmarks.timing import B, D, H, L, T, alternate, random_batch

REFERENCE = [f"model.num_layers={L}", f"model.hidden_size={H}", f"train.batch_size={B}", f"data.seq_length={T}"]


def _step(path, overrides, use_dense: bool, batch):
  from chorjax.config import load_config
  from chorjax.families.recurrent.steps import _train_step, create_train_state
  from chorjax.models import cells, fused, heads

  cells.dense = heads.dense = fused.dense if use_dense else (lambda x, w: x @ w)  # read when traced, below
  cfg = load_config(path, overrides)
  state, spec = create_train_state(cfg, batch["inputs"].shape[-1], 10)
  jitted = functools.partial(jax.jit, static_argnums=3, donate_argnums=0)(lambda *a: _train_step(*a))
  step = jitted.lower(state, batch, jax.random.key(0), spec).compile()
  cells.dense = heads.dense = fused.dense
  box = {"state": state}

  def run():
    box["state"], m = step(box["state"], batch, jax.random.key(0))
    return m["loss"]

  return run


def main(argv=None):
  ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
  ap.add_argument("--reps", type=int, default=10, help="timed repetitions of each step (default 10)")
  args = ap.parse_args(argv)
  from chorjax.config import load_config
  from chorjax.data.dataset import load_dataset
  from chorjax.runtime import keep_freed_memory

  keep_freed_memory()  # as the chorjax command does
  quick_dim = load_dataset(load_config("configs/quickstart.toml", []).data).features.dim
  setups = {
    "reference LSTM+MDN": (None, ["model.cell=lstm", "model.head=mdn", *REFERENCE], D, B, T),
    "reference LN-LSTM+MSE": (None, ["model.cell=lnlstm", "model.head=mse", *REFERENCE], D, B, T),
    "quickstart": ("configs/quickstart.toml", [], quick_dim, 32, 64),
  }
  rng = np.random.default_rng(0)
  for name, (path, overrides, dim, b, t) in setups.items():
    batch = random_batch(rng, b, t, dim)
    runs = {"plain": _step(path, overrides, False, batch), "dense": _step(path, overrides, True, batch)}
    med = alternate([(k, fn, jax.block_until_ready) for k, fn in runs.items()], args.reps)
    print(
      f"{name}: plain {med['plain'] * 1e3:.1f} ms, dense {med['dense'] * 1e3:.1f} ms, "
      f"dense / plain {med['dense'] / med['plain']:.3f}",
      flush=True,
    )


if __name__ == "__main__":
  main()
