"""GPU figures, on a machine with a CUDA GPU: chorjax's train step against PyTorch's on the same GPU (cuDNN's
``nn.LSTM`` / ``nn.GRU``; the LN-LSTM peer scripted), for the shipped configuration (2 x 192, batch 32 x 64)
and the reference one (3 x 256, batch 50 x 100), MDN head; sampling 1,000 frames at batch 1 and 64; and K
seeds trained as one vectorized program against K steps one after another.

    XLA_PYTHON_CLIENT_PREALLOCATE=false python -m benchmarks.gpu [--quick] [--out results_gpu.json]

Both frameworks run in this one process on one GPU; repetitions alternate and medians are reported.
Synthetic batches of 48 features (the models' arithmetic does not depend on the data).
"""

from __future__ import annotations

import argparse
import json
import os

os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")  # leave PyTorch its share of the GPU

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks.timing import alternate, compiled_train_step, random_batch

D, K, FRAMES = 48, 8, 1000
SHAPES = {"shipped": (2, 192, 32, 64), "reference": (3, 256, 50, 100)}  # layers, hidden, batch, frames


def _config(cell: str, layers: int, hidden: int, extra=()):
  from chorjax.config import load_config

  keys = [f"model.cell={cell}", "model.head=mdn", f"model.num_layers={layers}", f"model.hidden_size={hidden}"]
  return load_config(None, [*keys, f"model.num_mixtures={K}", "model.mdn_basis=pca", *extra])


def jax_step(cell: str, shape: str, kernel: str = "fused"):
  """chorjax's jitted train step on the GPU: ``run() -> loss``, and its compile seconds."""
  layers, hidden, b, t = SHAPES[shape]
  return compiled_train_step(_config(cell, layers, hidden, [f"model.lstm_kernel={kernel}"]), b, t, np.eye(D))


def torch_step(cell: str, shape: str, variant: str = "eager"):
  """The PyTorch peer's train step on the GPU (``benchmarks.torch_peer``), ``run() -> loss``."""
  import torch

  from benchmarks.torch_peer import Model, make_train_step

  layers, hidden, b, t = SHAPES[shape]
  torch.manual_seed(0)
  model = Model(cell, "mdn", D, hidden, layers, K, variant).cuda()
  step = make_train_step(model)
  x, y = torch.randn(b, t, D, device="cuda"), torch.randn(b, t, D, device="cuda")
  return lambda: step(x, y)


def _sync_torch(_):
  import torch

  torch.cuda.synchronize()


def train_steps(reps: int) -> dict:
  out = {}
  for shape in SHAPES:
    for cell in ("lstm", "lnlstm", "gru"):
      pairs = [(f"chorjax {cell} {shape}", jax_step(cell, shape)[0], jax.block_until_ready)]
      if cell == "lstm":
        pairs.append((f"chorjax lstm cudnn {shape}", jax_step(cell, shape, "cudnn")[0], jax.block_until_ready))
      peer = "script" if cell == "lnlstm" else "eager"
      pairs.append((f"torch {cell} {shape}", torch_step(cell, shape, peer), _sync_torch))
      times = alternate(pairs, reps)
      out.update(times)
      ours, theirs = times[f"chorjax {cell} {shape}"], times[f"torch {cell} {shape}"]
      out[f"ratio {cell} {shape}"] = theirs / ours  # > 1: chorjax faster
      print(f"{shape:9s} {cell:6s} chorjax {ours * 1e3:8.2f} ms  torch {theirs * 1e3:8.2f} ms  x{theirs / ours:.2f}")
      if cell == "lstm":
        cudnn = times[f"chorjax lstm cudnn {shape}"]
        out[f"ratio lstm cudnn {shape}"] = theirs / cudnn
        print(f"{shape:9s} lstm   chorjax model.lstm_kernel=cudnn {cudnn * 1e3:8.2f} ms  x{theirs / cudnn:.2f}")
  return out


def jax_sampler(batch: int, smooth: bool):
  from flax import nnx

  from chorjax.families.recurrent.generation import generate
  from chorjax.families.recurrent.recurrent_model import create_model
  from chorjax.sampling.controls import Draw

  layers, hidden, _, _ = SHAPES["shipped"]
  graphdef, params = nnx.split(create_model(_config("lstm", layers, hidden).model, D, 10, 0), nnx.Param)
  w = jax.nn.one_hot(jnp.zeros(batch, jnp.int32), 10)
  draw = Draw(noise_smoothing=0.75, noise_order=4, persistence=6.0, crossfade=0.8) if smooth else Draw()
  return lambda: generate(graphdef, params, w, jax.random.key(0), num_frames=FRAMES, draw=draw)


def torch_sampler(batch: int):
  """nn.LSTM (cuDNN) called on one frame at a time with its state carried, an MDN draw per frame."""
  import torch
  from torch import nn

  from benchmarks.torch_peer import mdn_draw

  layers, hidden, _, _ = SHAPES["shipped"]
  torch.manual_seed(0)
  lstm, out = nn.LSTM(D, hidden, layers, batch_first=True).cuda(), nn.Linear(hidden, K + 2 * K * D).cuda()

  @torch.no_grad()
  def run():
    x, state = torch.zeros(batch, 1, D, device="cuda"), None
    for _ in range(FRAMES):
      y, state = lstm(x, state)
      x = mdn_draw(out(y[:, 0]), K, D).unsqueeze(1)
    return x

  return run


def sampling(reps: int) -> dict:
  out = {}
  for batch in (1, 64):
    pairs = [
      (f"chorjax sample b{batch}", jax_sampler(batch, False), jax.block_until_ready),
      (f"chorjax sample smoothed b{batch}", jax_sampler(batch, True), jax.block_until_ready),
      (f"torch sample b{batch}", torch_sampler(batch), _sync_torch),
    ]
    times = alternate(pairs, reps)
    out.update(times)
    print(
      f"sampling {FRAMES} frames, batch {batch:2d}: chorjax {times[pairs[0][0]]:.3f} s (smoothed draw "
      f"{times[pairs[1][0]]:.3f} s), torch nn.LSTM loop {times[pairs[2][0]]:.3f} s"
    )
  return out


def vectorized(k: int, reps: int) -> dict:
  """Seconds of one step of one run, and of one vectorized step of ``k`` runs (the shipped shape)."""
  from chorjax.families.recurrent.steps import _train_step, create_train_state, train_step
  from chorjax.training.vectorized import vec_train_step

  layers, hidden, b, t = SHAPES["shipped"]
  made = [create_train_state(_config("lstm", layers, hidden, [f"train.seed={s}"]), D, 10, np.eye(D)) for s in range(k)]
  spec = made[0][1]
  batch = random_batch(np.random.default_rng(0), b, t, D)
  batches = jax.device_put(jax.tree.map(lambda x: np.stack([x] * k), batch))
  box = {"one": made[0][0], "all": jax.tree.map(lambda *xs: jnp.stack(xs), *[s for s, _ in made])}
  keys = jnp.stack([jax.random.key_data(jax.random.key(s)) for s in range(k)])
  hyper = {"lr_scale": jnp.ones(k), "noise": jnp.full(k, 0.075)}
  batch = jax.device_put(batch)

  def one():
    box["one"], m = train_step(box["one"], batch, jax.random.key(0), spec)
    return m["loss"]

  def together():
    box["all"], m = vec_train_step(box["all"], batches, keys, hyper, spec, _train_step)
    return m["loss"]

  times = alternate([("one", one, jax.block_until_ready), ("together", together, jax.block_until_ready)], reps)
  speedup = k * times["one"] / times["together"]
  print(
    f"{k} seeds: one step {times['one'] * 1e3:.2f} ms, {k} as one program "
    f"{times['together'] * 1e3:.2f} ms: x{speedup:.2f}"
  )
  return {
    f"vectorized k{k} one": times["one"],
    f"vectorized k{k} together": times["together"],
    f"vectorized k{k} x": speedup,
  }


def main(argv=None):
  ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
  ap.add_argument("--quick", action="store_true", help="fewer repetitions")
  ap.add_argument("--out", default="results_gpu.json")
  args = ap.parse_args(argv)
  import torch

  reps = 10 if args.quick else 30
  info = {
    "device": torch.cuda.get_device_name(0),
    "jax": jax.__version__,
    "jax_devices": [str(d) for d in jax.devices()],
    "torch": torch.__version__,
    "cudnn": torch.backends.cudnn.version(),
  }
  print(json.dumps(info))
  results = {"info": info, **train_steps(reps)}
  results.update(sampling(max(3, reps // 5)))
  results.update(vectorized(8, reps))
  with open(args.out, "w") as f:
    json.dump(results, f, indent=2)
  print(f"wrote {args.out}")


if __name__ == "__main__":
  main()
