"""Vectorized training: K runs of one shape trained as one jitted, vmapped program.

Points that differ only in ``VECTOR_KEYS`` (training seed, learning rate, input noise) and in what each
point writes (``name``, ``sample.*``, ``log.*``) share every shape, so their parameters, optimizer
states, RNG keys and batches are stacked on a leading axis and one ``jax.vmap`` of the train step
advances all of them: on a CPU the per-step overhead and the small matrix products of one quickstart
run leave most of the machine idle, and K runs fill it.

What each point gets is exactly what it would get alone: its own initialization (``train.seed``), its
own window sampler and RNG stream, its own input noise (a traced value), and its own learning rate (the
optimizer's update computed at the first point's rate and scaled by ``lr_k / lr_0``: every optimizer
chorjax offers is linear in the rate after clipping, so this differs from a lone run by rounding only),
and its batch in its own shares where ``train.batch_parts`` asks (one after another inside the program,
where a lone run computes them in threads).
Each point is written as an ordinary run directory (config.json, metrics.jsonl, TensorBoard events,
checkpoints with their own meta, the end sample), so ``sample``, ``eval``, ``compare`` and resuming
work unchanged. Points resume together when their latest checkpoints are at one step
(``NotAligned`` otherwise: train them apart). Not vectorized: the TensorBoard figure of a generated
sample (each point's end sample is written as usual) and data-parallel training.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from chorjax import checkpoint as ckpt
from chorjax.config import Config
from chorjax.data.dataset import WindowSampler, dataset_notes, eval_windows, load_dataset
from chorjax.errors import UserError
from chorjax.families import family_of
from chorjax.run import run_meta
from chorjax.training import end_of_run
from chorjax.training.driver import (
  _check_saved_config,
  _keep_aside,
  _restore_or_init,
  _truncate_metrics,
  _write_config,
  check_workdir,
  sized_to_data,
  workdir_lock,
)
from chorjax.training.loop import Loop, MetricsLog, TrainingDiverged, best_checkpoint_hook, stop_on_signals
from chorjax.training.points import NotAligned, check_group


@functools.partial(jax.jit, static_argnums=(4, 5), donate_argnums=0)
def vec_train_step(states, batches, keys, hyper, spec, step):
  """``K`` train steps at once: every argument but ``spec`` and the family's ``step`` (``Family.vector_step``)
  is stacked on a leading axis."""
  one = lambda state, batch, key, lr_scale, noise: step(state, batch, key, spec, lr_scale, noise)
  return jax.vmap(one)(states, batches, keys, hyper["lr_scale"], hyper["noise"])


@functools.partial(jax.jit, static_argnums=(2, 3))
def vec_eval_step(params, batch, graphdef, loss):
  """Each point's validation loss on the same windows, ``[K]`` (``loss``: the family's, ``Family.vector_step``)."""
  return jax.vmap(lambda p: loss(p, batch, graphdef))(params)


def _take(tree, k: int):
  return jax.tree.map(lambda x: x[k], tree)


class VecLoop(Loop):
  """The training loop over stacked points: listener ``k`` hears point ``k``'s scalars. ``val_loss`` and
  ``losses`` hold the points' mean; ``vec_val`` and ``vec_losses`` each point's."""

  def __init__(self, *args):
    super().__init__(*args)
    self.vec_losses: dict[int, np.ndarray] = {}
    self.vec_val: np.ndarray | None = None

  def publish(self, step: int, metrics: dict, val_loss=None) -> None:
    losses = np.asarray(metrics["loss"], np.float64)
    bad = np.flatnonzero(~np.isfinite(losses))
    if len(bad):
      where = f"step {self.last_good}" if self.last_good is not None else "none (no checkpoint was written yet)"
      raise TrainingDiverged(
        f"point {bad[0]}: non-finite loss ({losses[bad[0]]}) at step {step}; training stopped; "
        f"last good checkpoint: {where}"
      )
    self.losses[step], self.vec_losses[step] = float(losses.mean()), losses
    host = {k: np.asarray(v) for k, v in metrics.items()}
    vals = [None] * len(losses) if val_loss is None or self.vec_val is None else [float(v) for v in self.vec_val]
    for k, listener in enumerate(self.listeners):
      listener(step, float(losses[k]), {n: v[k] for n, v in host.items()}, vals[k])


def _quiet(cfg: Config) -> Config:
  return dataclasses.replace(cfg, log=dataclasses.replace(cfg.log, progress="none"))


def train_vectorized(cfgs, workdirs, *, force: bool = False) -> list[dict]:
  """Trains the points ``cfgs`` (one run directory each in ``workdirs``) as one vectorized program of their
  family's step (``Family.vector_step``); returns each point's summary, as ``training.train_and_evaluate`` does.

  Raises:
    UserError: points that differ in a key that cannot be vectorized (``points.check_group``).
    NotAligned: a family that trains its points apart, or points whose latest checkpoints are at different
      steps.
  """
  cfgs, workdirs = list(cfgs), [Path(w).absolute() for w in workdirs]
  check_group(cfgs)
  if any(c.train.patience for c in cfgs):
    raise UserError("train.patience: not with several seeds in one program (each would end apart); train them apart")
  for w in workdirs:  # every point's folder, before any is locked or written
    check_workdir(w, force)
  with contextlib.ExitStack() as stack:
    for w in workdirs:
      stack.enter_context(workdir_lock(w))
    keep_old = [_check_saved_config(w, c, force) for w, c in zip(workdirs, cfgs)]
    ds = load_dataset(cfgs[0].data)
    sized = [sized_to_data(c, ds) for c in cfgs]
    cfgs = [c for c, _ in sized]
    for line in [*dataset_notes(ds), *([sized[0][1]] if sized[0][1] else [])]:
      print(line, file=sys.stderr if line.startswith("warning") else sys.stdout, flush=True)
    managers = [ckpt.create_manager(w, keep=c.train.keep_checkpoints) for w, c in zip(workdirs, cfgs)]
    for m in managers:
      stack.callback(ckpt.close_quietly, m)
    restored = [_restore_or_init(c, w, ds, m, None) for c, w, m in zip(cfgs, workdirs, managers)]
    starts = [s for _, _, s in restored]
    if len(set(starts)) > 1:
      raise NotAligned(f"points are at different steps ({', '.join(map(str, starts))}): train them apart")
    for w, c, keep in zip(workdirs, cfgs, keep_old):
      if keep:
        _keep_aside(w)
      _write_config(w, c)
      _truncate_metrics(w / "metrics.jsonl", starts[0])
    return _run(cfgs, workdirs, ds, managers, restored, stack)


def _run(cfgs, workdirs, ds, managers, restored, stack) -> list[dict]:
  t_start, start, spec = time.time(), restored[0][2], restored[0][1]
  c0, k_points = cfgs[0], len(cfgs)
  states = jax.tree.map(lambda *xs: jnp.stack(xs), *[s for s, _, _ in restored])
  hyper = {
    "lr_scale": jnp.asarray([c.optim.lr / c0.optim.lr if c0.optim.lr > 0 else 1.0 for c in cfgs], jnp.float32),
    "noise": jnp.asarray([c.train.input_noise for c in cfgs], jnp.float32),
  }
  keys = jnp.stack([jax.random.key_data(jax.random.key(c.train.seed)) for c in cfgs])
  samplers = [WindowSampler(ds.train, c0.data.seq_length, c0.train.batch_size, c.train.seed) for c in cfgs]
  get_batch = lambda step: jax.tree.map(lambda *xs: np.stack(xs), *[s.batch(step) for s in samplers])
  val = eval_windows(ds.val, c0.data.seq_length, c0.train.val_windows)
  parts = family_of(c0).vector_step()
  assert parts is not None  # check_group refused a family without one
  step, loss = parts
  step_fn = lambda st, b, k: vec_train_step(st, b, k, hyper, spec, step)
  loop = VecLoop(step_fn, get_batch, keys, states, start, c0.train.num_steps)
  for k, (c, w) in enumerate(zip(cfgs, workdirs)):
    log = MetricsLog(w, c if k == 0 else _quiet(c), start)
    stack.callback(log.close)
    loop.listeners.append(log)

  def evaluate(_: Loop) -> None:
    if val:
      loop.vec_val = np.asarray(vec_eval_step(loop.state["params"], val, spec.graphdef, loss))
      loop.val_loss = float(loop.vec_val.mean())
    loop.flush()

  loop.add_hook(evaluate, c0.train.eval_every)
  _checkpoint_hooks(loop, cfgs, managers, ds, bool(val))
  samples: list[dict] = [{} for _ in cfgs]

  def end_samples(_: Loop) -> None:  # each point as it would end alone (end_of_run.standard)
    for k, (c, w) in enumerate(zip(cfgs, workdirs)):
      if c.train.num_steps > 0 and loop.step >= c.train.num_steps:  # finished, not stopped
        finished = end_of_run.Finished(w, ds, c, spec.graphdef, _take(loop.state["params"], k))
        for hook in end_of_run.standard(c):
          samples[k].update(hook(finished))

  loop.end_hooks.append(end_samples)
  print(f"training {k_points} points as one program: {', '.join(str(w.name) for w in workdirs)}", flush=True)
  with stop_on_signals() as stop:
    loop.stop = stop
    loop.run()
  return [_summary(loop, k, start, t_start, samples[k]) for k in range(k_points)]


def _checkpoint_hooks(loop: VecLoop, cfgs, managers, ds, has_val: bool) -> None:
  """Each point's checkpoints, as it would save them alone: every ``checkpoint_every`` steps, its best where it
  happens (``train.keep = "best"``), this step's on a stop signal; and the end waits for the writes."""
  c0 = cfgs[0]

  def save_point(k: int) -> None:
    val_k = None if loop.val_loss is None or loop.vec_val is None else float(loop.vec_val[k])
    ckpt.save(managers[k], loop.step, _take(loop.state, k), run_meta(cfgs[k], ds.features, loop.step, ds), val_k)

  def save(_: Loop) -> None:
    loop.flush()
    for k in range(len(cfgs)):
      save_point(k)
    loop.last_good = loop.step

  def best_of(k: int):  # point k's own best, as best_checkpoint_hook keeps a run's alone
    def save_k(_: Loop) -> None:
      loop.flush()
      save_point(k)

    return best_checkpoint_hook(managers[k], save_k, lambda _: None if loop.vec_val is None else float(loop.vec_val[k]))

  def save_now(_: Loop) -> None:
    if managers[0].latest_step() != loop.step:
      save(loop)
    for m in managers:
      ckpt.wait(m)

  def wait(_: Loop) -> None:
    for m in managers:
      ckpt.wait(m)

  loop.add_hook(save, c0.train.checkpoint_every)
  if c0.train.keep == "best" and has_val:
    for k in range(len(cfgs)):
      loop.add_hook(best_of(k), c0.train.eval_every or c0.train.num_steps)
  loop.end_hooks.append(wait)
  loop.on_stop = save_now


def _summary(loop: VecLoop, k: int, start: int, t_start: float, samples: dict) -> dict:
  losses = {s: float(v[k]) for s, v in loop.vec_losses.items()}
  out = {
    "start_step": start,
    "final_step": loop.step,
    "train_losses": losses,
    "seconds": time.time() - t_start,
    "compile_s": loop.compile_s,
  }
  if losses:
    out["final_train_loss"] = losses[max(losses)]
  if loop.val_loss is not None and loop.vec_val is not None:
    out["final_val_loss"] = float(loop.vec_val[k])
  if samples:
    out["samples"] = samples
  return out
