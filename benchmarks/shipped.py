"""The shipped configuration's train step on this machine's CPU: chorjax's LSTM against PyTorch's ``nn.LSTM``
for the quickstart's shape (2 x 192, batch 32 x 64) and the reference one (3 x 256, batch 50 x 100), with the
quickstart's MDN head (8 diagonal components in the data's principal axes) and with an MSE head.

    python -m benchmarks.shipped [--reps N] [--out benchmarks/results_shipped.json]

Both frameworks in this one process, repetitions alternating after one untimed round, medians reported (as
``benchmarks.run``); chorjax's step both as one program and with ``train.batch_parts = 2`` (the batch's two
halves side by side in threads). Synthetic batches of 48 features. BENCHMARKS.md's opening table is this
script's output; ``python -m benchmarks.run`` runs it too.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import jax
import numpy as np

from benchmarks.timing import alternate, compiled_train_step, random_batch

D, K = 48, 8
SHAPES = {"shipped": (2, 192, 32, 64), "reference": (3, 256, 50, 100)}  # layers, hidden, batch, frames
HERE = Path(__file__).resolve().parent
OUT = HERE / "results_shipped.json"


def _config(head: str, shape: str, *more: str):
  """The LSTM config of ``shape`` with ``head`` (and ``more`` keys), and the MDN's basis (None for MSE)."""
  from chorjax.config import load_config

  layers, hidden, _, _ = SHAPES[shape]
  keys = ["model.cell=lstm", f"model.head={head}", f"model.num_layers={layers}", f"model.hidden_size={hidden}"]
  basis = ["model.mdn_basis=pca"] if head == "mdn" else []
  cfg = load_config(None, [*keys, f"model.num_mixtures={K}", *basis, *more])
  return cfg, np.eye(D) if head == "mdn" else None


def jax_step(head: str, shape: str):
  """chorjax's jitted LSTM train step: ``run() -> loss`` and its compile seconds."""
  _, _, b, t = SHAPES[shape]
  cfg, basis = _config(head, shape)
  return compiled_train_step(cfg, b, t, basis)


def parted_step(head: str, shape: str, parts: int = 2):
  """chorjax's LSTM train step with ``train.batch_parts = parts``: the shares' gradients in threads, then the
  update (``run() -> loss``)."""
  from chorjax.families.recurrent.steps import create_train_state, parted_train_step

  _, _, b, t = SHAPES[shape]
  cfg, basis = _config(head, shape, f"train.batch_parts={parts}")
  state, spec = create_train_state(cfg, D, 10, basis)
  batch, key, box = random_batch(np.random.default_rng(0), b, t, D), jax.random.key(0), {"state": state}

  def run():
    box["state"], m = parted_train_step(box["state"], batch, key, spec)
    return m["loss"]

  return run


def torch_step(head: str, shape: str):
  """PyTorch's ``nn.LSTM`` with the same head, Adam and global-norm clipping, eager."""
  import torch

  from benchmarks.torch_peer import Model, make_train_step

  layers, hidden, b, t = SHAPES[shape]
  torch.manual_seed(0)
  step = make_train_step(Model("lstm", head, D, hidden, layers, K, "eager"))
  x, y = torch.randn(b, t, D), torch.randn(b, t, D)
  return lambda: step(x, y)


def measure(reps: int) -> dict:
  """Every shape x head: chorjax one program, with two shares, and ``nn.LSTM`` (medians, ratios); prints a line
  each. The caller sets up the process (``keep_freed_memory``, torch's threads)."""
  import torch

  from chorjax.compare import machine_info

  res = {"machine": machine_info(), "jax": jax.__version__, "torch": torch.__version__, "reps": reps}
  for shape in SHAPES:
    for head in ("mdn", "mse"):
      ours, compile_s = jax_step(head, shape)
      parted = parted_step(head, shape)
      pairs = [("chorjax", ours, jax.block_until_ready), ("chorjax_parts2", parted, jax.block_until_ready)]
      times = alternate([*pairs, ("torch", torch_step(head, shape), lambda x: x.item())], reps)
      name = f"lstm {head} {shape}"
      res[name] = {
        **times,
        "ratio": times["torch"] / times["chorjax"],
        "ratio_parts2": times["torch"] / times["chorjax_parts2"],
        "compile_s": compile_s,
      }
      print(
        f"{name:22s} chorjax {times['chorjax'] * 1e3:7.1f} ms (x{res[name]['ratio']:.2f}), batch in 2 shares "
        f"{times['chorjax_parts2'] * 1e3:7.1f} ms (x{res[name]['ratio_parts2']:.2f}), torch nn.LSTM "
        f"{times['torch'] * 1e3:7.1f} ms (compile {compile_s:.1f} s)",
        flush=True,
      )
  return res


def main(argv=None) -> None:
  ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
  ap.add_argument("--reps", type=int, default=15, help="timed repetitions per step (default 15)")
  ap.add_argument("--out", default=str(OUT))
  args = ap.parse_args(argv)
  from chorjax.runtime import keep_freed_memory

  keep_freed_memory()  # as the chorjax command does; the PyTorch peer in this process gains too
  import torch

  torch.set_num_threads(os.cpu_count() or 1)
  Path(args.out).write_text(json.dumps(measure(args.reps), indent=2))
  print(f"wrote {args.out}")


if __name__ == "__main__":
  main()
