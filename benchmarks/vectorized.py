"""Vectorized sweeps: K quickstart seeds trained as one program against the same K runs one by one.

    python -m benchmarks.vectorized                 # K = 4 and 8, 300 steps each (about 15 minutes)
    python -m benchmarks.vectorized --steps 100     # quicker

Two figures per K, both on the quickstart config (configs/quickstart.toml, its data and model):

- **steady step**: the median time of one vectorized step of K points over K times the median time of
  one lone step (the heart of the matter: how much of the machine one small model leaves idle);
- **whole training**: the wall time of `train_vectorized` on K fresh points over the summed wall time of
  the same K points trained one by one with `train_and_evaluate` (compile, data, checkpoints and the
  validation evaluations included; a 10-frame end sample on both sides).

- **against PyTorch** (``--torch``; needs ``pip install -e '.[bench]'``): the steady step of K points as
  K PyTorch runs of the same model (the LN-LSTM of ``benchmarks/torch_peer.py`` in the form
  ``--torch-form`` names, by default its eager loop: on this CPU faster than the scripted one; batch,
  window, layers, sizes and MDN head as the quickstart's), one after another
  (K x its lone step, all cores) and as K processes at once sharing the cores (each with cores / K
  threads, at least one; the median step of each after a common start, the slowest counted).

Writes ``benchmarks/vectorized.json`` and prints a table for BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

import jax
import numpy as np

HERE = Path(__file__).resolve().parent


def _cfgs(k: int, steps: int):
  from chorjax.config import load_config

  base = ["log.tensorboard=false", "log.progress=none", "sample.frames=10", f"train.num_steps={steps}"]
  return [load_config("configs/quickstart.toml", [*base, f"train.seed={s}"]) for s in range(k)]


def steady_steps(k: int, reps: int = 30) -> dict:
  """Median seconds of one lone step and of one vectorized step of ``k`` points."""
  from chorjax.data.dataset import WindowSampler, load_dataset
  from chorjax.families.recurrent.steps import _train_step, create_train_state, train_step
  from chorjax.training.vectorized import vec_train_step

  cfgs = _cfgs(k, 100)
  ds = load_dataset(cfgs[0].data)
  made = [create_train_state(c, ds.features.dim, ds.num_motions) for c in cfgs]
  spec = made[0][1]
  samplers = [WindowSampler(ds.train, cfgs[0].data.seq_length, cfgs[0].train.batch_size, c.train.seed) for c in cfgs]
  box = {"one": made[0][0], "all": jax.tree.map(lambda *xs: jax.numpy.stack(xs), *[s for s, _ in made])}
  key = jax.random.key(0)
  keys = jax.numpy.stack([jax.random.key_data(jax.random.key(c.train.seed)) for c in cfgs])
  hyper = {"lr_scale": jax.numpy.ones(k), "noise": jax.numpy.full(k, cfgs[0].train.input_noise)}

  def one(step):
    box["one"], m = train_step(box["one"], samplers[0].batch(step), key, spec)
    return m["loss"]

  def together(step):
    batch = jax.tree.map(lambda *xs: np.stack(xs), *[s.batch(step) for s in samplers])
    box["all"], m = vec_train_step(box["all"], batch, keys, hyper, spec, _train_step)
    return m["loss"]

  out = {}
  for name, fn in (("one", one), ("together", together)):
    for s in range(3):  # compile and settle
      jax.block_until_ready(fn(s))
    times = []
    for s in range(reps):
      t = time.perf_counter()
      jax.block_until_ready(fn(3 + s))
      times.append(time.perf_counter() - t)
    out[name] = float(np.median(times))
  return out


def _torch_steps(args) -> list[float]:
  """In a worker process: ``reps`` step times of the PyTorch peer at the quickstart's shapes."""
  dim, threads, reps, barrier, seed, form = args
  import torch

  from benchmarks.torch_peer import Model, make_train_step

  torch.set_num_threads(threads)
  torch.manual_seed(seed)
  cfg = _cfgs(1, 1)[0]
  b, t, m = cfg.train.batch_size, cfg.data.seq_length, cfg.model
  model = Model(m.cell, m.head, dim, m.hidden_size, m.num_layers, m.num_mixtures, form)
  step = make_train_step(model)
  x, y = torch.randn(b, t, dim), torch.randn(b, t, dim)
  for _ in range(3):
    step(x, y).item()
  if barrier is not None:
    barrier.wait()
  times = []
  for _ in range(reps):
    t0 = time.perf_counter()
    step(x, y).item()
    times.append(time.perf_counter() - t0)
  return times


def torch_steps(k: int, form: str, reps: int = 30) -> dict:
  """Seconds per step of K PyTorch points: one after another (K x a lone step on all cores) and K
  processes at once (the slowest process's median step)."""
  import multiprocessing as mp
  import os

  from chorjax.data.dataset import load_dataset

  dim = load_dataset(_cfgs(1, 1)[0].data).features.dim
  cores = os.cpu_count() or 1
  ctx = mp.get_context("spawn")
  with ctx.Pool(1) as pool:
    lone = float(np.median(pool.map(_torch_steps, [(dim, cores, reps, None, 0, form)])[0]))
  with ctx.Manager() as manager:
    barrier = manager.Barrier(k)
    with ctx.Pool(k) as pool:
      per = pool.map(_torch_steps, [(dim, max(1, cores // k), reps, barrier, i, form) for i in range(k)])
  return {"torch_lone": lone, "torch_sequential": k * lone, "torch_parallel": max(float(np.median(t)) for t in per)}


def whole_training(k: int, steps: int) -> dict:
  from chorjax.training.driver import train_and_evaluate
  from chorjax.training.vectorized import train_vectorized

  cfgs = _cfgs(k, steps)
  with tempfile.TemporaryDirectory() as d:
    t = time.perf_counter()
    train_vectorized(cfgs, [Path(d) / f"v{i}" for i in range(k)])
    together = time.perf_counter() - t
    t = time.perf_counter()
    for i, c in enumerate(cfgs):
      train_and_evaluate(c, Path(d) / f"a{i}")
    alone = time.perf_counter() - t
  return {"together_s": together, "one_by_one_s": alone}


def main(argv=None):
  ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
  ap.add_argument("--steps", type=int, default=300, help="training steps per point (default 300)")
  ap.add_argument("--ks", type=int, nargs="+", default=[4, 8], help="points trained together (default 4 8)")
  ap.add_argument("--torch", action="store_true", help="also K PyTorch runs, one by one and in parallel processes")
  forms = ["eager", "script", "compile"]
  ap.add_argument("--torch-form", default="eager", choices=forms, help="the LN-LSTM peer's form (default eager)")
  ap.add_argument("--no-training", action="store_true", help="steady steps only (skip the whole trainings)")
  args = ap.parse_args(argv)
  results = {"machine": platform.processor() or platform.machine(), "jax": jax.__version__, "steps": args.steps}
  if args.torch:
    import torch

    results["torch"] = torch.__version__
    results["torch_form"] = args.torch_form
  print(
    "| K | lone step | K points' step | step ratio (K together / K alone) | training: together | one by one | ratio |"
  )
  print("|---|---|---|---|---|---|---|")
  for k in args.ks:
    s = steady_steps(k)
    r = {**s, "step_ratio": s["together"] / (k * s["one"])}
    if not args.no_training:
      w = whole_training(k, args.steps)
      r.update(w, wall_ratio=w["together_s"] / w["one_by_one_s"])
    if args.torch:
      p = torch_steps(k, args.torch_form)
      r.update(p, over_torch_sequential=s["together"] / p["torch_sequential"])
      r["over_torch_parallel"] = s["together"] / p["torch_parallel"]
    results[f"k{k}"] = r
    wall = "- | - | -"
    if "wall_ratio" in r:
      wall = f"{r['together_s']:.0f} s | {r['one_by_one_s']:.0f} s | {r['wall_ratio']:.2f}"
    step = f"{s['one'] * 1e3:.0f} ms | {s['together'] * 1e3:.0f} ms | {r['step_ratio']:.2f}"
    print(f"| {k} | {step} | {wall} |", flush=True)
    if args.torch:
      print(
        f"  K = {k} PyTorch points ({args.torch_form} LN-LSTM): lone step {p['torch_lone'] * 1e3:.0f} ms, "
        f"one after another {p['torch_sequential'] * 1e3:.0f} ms, "
        f"{k} processes at once {p['torch_parallel'] * 1e3:.0f} ms; "
        f"chorjax vectorized / those: {r['over_torch_sequential']:.2f}, {r['over_torch_parallel']:.2f}",
        flush=True,
      )
  (HERE / "vectorized.json").write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
  main()
