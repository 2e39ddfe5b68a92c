"""What every timing here shares: the reference model's sizes, a round-robin timer, a random training batch
and chorjax's compiled train step."""

from __future__ import annotations

import time

import jax
import numpy as np

from chorjax.families.recurrent.steps import create_train_state, train_step

B, T, D, H, L, K = 50, 100, 48, 256, 3, 8


def timed(fn, sync):
  t = time.perf_counter()
  sync(fn())
  return time.perf_counter() - t


def alternate(pairs, reps):
  """Runs the (name, fn, sync) entries round-robin ``reps`` times after one untimed round (the heap and
  caches settle over the first calls); returns name -> median seconds."""
  for _, fn, sync in pairs:
    sync(fn())
  times = {name: [] for name, _, _ in pairs}
  for _ in range(reps):
    for name, fn, sync in pairs:
      times[name].append(timed(fn, sync))
  return {k: float(np.median(v)) for k, v in times.items()}


def random_batch(rng, b: int, t: int, d: int) -> dict:
  """A training batch of ``b`` windows of ``t`` random frames of ``d`` features (10 motion ids)."""
  return {
    "inputs": rng.normal(size=(b, t, d)).astype(np.float32),
    "targets": rng.normal(size=(b, t, d)).astype(np.float32),
    "motion_ids": rng.integers(0, 10, b).astype(np.int32),
  }


def compiled_train_step(cfg, b: int, t: int, basis=None):
  """chorjax's train step for ``cfg`` on a random batch of ``b`` windows of ``t`` frames (``basis``: the MDN's
  principal axes where ``model.mdn_basis = "pca"``), compiled: ``(run() -> loss, compile seconds)``."""
  state, spec = create_train_state(cfg, D, 10, basis)
  batch = jax.device_put(random_batch(np.random.default_rng(0), b, t, D))
  key, box = jax.random.key(0), {"state": state}
  t0 = time.perf_counter()
  step = train_step.lower(state, batch, key, spec).compile()  # trace + XLA compile, timed apart from running
  compile_s = time.perf_counter() - t0

  def run():
    box["state"], m = step(box["state"], batch, key)
    return m["loss"]

  return run, compile_s
