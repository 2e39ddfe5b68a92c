"""The training loop and its hooks: :class:`Loop` only runs a family's jitted steps; everything periodic is a
:class:`Hook` with a ``due(step, every, total)`` rule (evaluation, patience, checkpoints, TensorBoard figures),
and metrics reach listeners (``metrics.jsonl``, TensorBoard, progress) one step late. ``chorjax.training.driver``
drives it for a run; a new training mode brings a step function and hooks, not a new loop."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import signal
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import jax
import numpy as np
from jax.experimental import multihost_utils
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
from tensorboardX import SummaryWriter

from chorjax import checkpoint as ckpt
from chorjax.config import Config
from chorjax.data.dataset import Dataset
from chorjax.errors import Interrupted, UserError
from chorjax.families import family_of
from chorjax.render.plot import require_matplotlib
from chorjax.sampling.controls import Controls, with_ceiling


class TrainingDiverged(UserError):
  """A non-finite loss; the message names the step and the last good checkpoint."""


# ---------------------------------------------------------------- the loop


def due(step: int, every: int, total: int) -> bool:
  """Whether a periodic action runs after ``step`` of ``total`` steps: every ``every`` steps and at
  the last step (``every = 0``: at the last step only)."""
  return step == total or (every > 0 and step % every == 0)


@dataclasses.dataclass
class Hook:
  """``fn(loop)`` after every ``every`` steps, and after the last step when ``at_last``."""

  fn: Callable[[Loop], None]
  every: int
  at_last: bool = True

  def is_due(self, step: int, total: int) -> bool:
    if not self.at_last and step == total:
      return self.every > 0 and step % self.every == 0
    return due(step, self.every, total)


class Loop:
  """Runs ``step_fn`` from ``start`` to ``total``; hooks do the rest.

  After each step the loop publishes the previous step's metrics (pulled to the host one step late,
  so the device stays busy) to the listeners, then runs the hooks that are due. A hook that needs the
  current step's metrics checked first (a checkpoint must not save a diverged state) calls
  :meth:`flush`. ``loop.val_loss`` holds the current step's validation loss once an evaluation hook
  has set it.
  """

  def __init__(self, step_fn, get_batch, key, state, start: int, total: int):
    self.step_fn, self.get_batch, self.key = step_fn, get_batch, key
    self.state, self.step, self.total = state, start, total
    self.hooks: list[Hook] = []
    self.listeners: list[Callable[[int, float, dict, float | None], None]] = []
    self.end_hooks: list[Callable[[Loop], None]] = []
    self.pending: tuple[int, dict] | None = None
    self.val_loss: float | None = None
    self.last_good: int | None = start if start > 0 else None
    self.losses: dict[int, float] = {}
    self.compile_s: float | None = None
    self.stop: Callable[[], int | None] = lambda: None  # a signal number once one asks to stop
    self.ended: str | None = None  # why training ended before ``total`` (a hook's reason), e.g. patience
    self.on_stop: Callable[[Loop], None] = lambda loop: None

  def add_hook(self, fn, every: int, at_last: bool = True) -> None:
    self.hooks.append(Hook(fn, every, at_last))

  def publish(self, step: int, metrics: dict, val_loss: float | None = None) -> None:
    loss = float(metrics["loss"])
    if not math.isfinite(loss):
      where = f"step {self.last_good}" if self.last_good is not None else "none (no checkpoint was written yet)"
      raise TrainingDiverged(
        f"non-finite loss ({loss}) at step {step}; training stopped; last good checkpoint: {where}"
      )
    self.losses[step] = loss
    for listener in self.listeners:
      listener(step, loss, metrics, val_loss)

  def flush(self) -> None:
    """Publishes the current step's metrics now (with ``val_loss`` if an evaluation set it)."""
    if self.pending is not None:
      pending, self.pending = self.pending, None
      self.publish(*pending, val_loss=self.val_loss if pending[0] == self.step else None)

  def run(self) -> None:
    for step in range(self.step, self.total):
      t0 = time.time()
      self.state, metrics = self.step_fn(self.state, self.get_batch(step), self.key)
      if self.compile_s is None:
        jax.block_until_ready(metrics["loss"])
        self.compile_s = time.time() - t0
      self.flush()  # the previous step's metrics, one step late
      self.step, self.pending, self.val_loss = step + 1, (step + 1, metrics), None
      for hook in self.hooks:
        if hook.is_due(self.step, self.total):
          hook.fn(self)
      if self.ended is not None:
        break
      signum = self.stop()
      if signum is not None and self.step < self.total:
        self.flush()
        self.on_stop(self)
        name = signal.Signals(signum).name
        raise Interrupted(
          f"{name} at step {self.step}/{self.total}: checkpoint saved; the same command resumes", 128 + signum
        )
    self.flush()
    for fn in self.end_hooks:
      fn(self)


@contextlib.contextmanager
def stop_on_signals():
  """Yields a function that returns SIGINT's or SIGTERM's number once one has arrived (else None).

  The first signal asks the loop to finish its step and save; a second one stops at once (the usual
  Ctrl-C). Off the main thread (where Python cannot install handlers) nothing changes.
  """
  if threading.current_thread() is not threading.main_thread():
    yield lambda: None
    return
  got: list[int] = []

  def handler(signum, frame):
    if got:  # a second signal: stop now
      raise KeyboardInterrupt
    got.append(signum)

  old = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
  try:
    yield lambda: got[0] if got else None
  finally:
    for s, h in old.items():
      signal.signal(s, h)


def agreed_stop(local: Callable[[], int | None]) -> Callable[[], int | None]:
  """For several processes: after every step they exchange whether a signal arrived (one tiny
  all-gather), so that all stop, and save the collective checkpoint, at the same step when any one is
  signalled (a preempted host gets SIGTERM alone)."""

  def stop() -> int | None:
    every = np.asarray(multihost_utils.process_allgather(np.int32(local() or 0)))
    return int(every.max()) or None

  return stop


# ---------------------------------------------------------------- listeners and hooks


class _Progress:
  """A rich progress bar on a terminal; in Jupyter one line rewritten in place (``inline``); plain periodic
  lines otherwise (CI, cluster logs)."""

  def __init__(self, mode: str, total: int, start: int):
    if mode == "auto":
      mode = "bar" if sys.stdout.isatty() else "inline" if "ipykernel" in sys.modules else "lines"
    self.mode = mode
    self.total, self.bar = total, None
    if self.mode == "bar":
      self.bar = Progress(
        TextColumn("train"), BarColumn(), MofNCompleteColumn(), TextColumn("{task.fields[info]}"), TimeRemainingColumn()
      )
      self.task = self.bar.add_task("train", total=total, completed=start, info="")
      self.bar.start()

  def update(self, step: int, row: dict, eta_s: float):
    info = f"loss {row['train_loss']:.4g}" + (f" val {row['val_loss']:.4g}" if "val_loss" in row else "")
    if self.bar is not None:
      self.bar.update(self.task, completed=step, info=info)
    elif self.mode in ("lines", "inline"):
      line = f"step {step}/{self.total} {info} {row.get('steps_per_s', 0):.1f} steps/s ETA {eta_s:.0f}s"
      print(f"\r{line}" if self.mode == "inline" else line, end="" if self.mode == "inline" else "\n", flush=True)

  def close(self):
    if self.bar is not None:
      self.bar.stop()
    if self.mode == "inline":
      print(flush=True)


class MetricsLog:
  """Writes a row to ``metrics.jsonl`` and TensorBoard, and updates the progress display, every
  ``log_every`` steps, at the last step, and whenever a validation loss was measured."""

  def __init__(self, workdir: Path, cfg: Config, start: int):
    self.path, self.log_every, self.total = workdir / "metrics.jsonl", cfg.train.log_every, cfg.train.num_steps
    self.writer = None
    if cfg.log.tensorboard:
      self.writer = SummaryWriter(str(workdir), flush_secs=10)
    self.progress = _Progress(cfg.log.progress, self.total, start)
    self.t_last, self.step_last = time.time(), start

  def __call__(self, step: int, loss: float, metrics: dict, val_loss: float | None) -> None:
    if not due(step, self.log_every, self.total) and val_loss is None:
      return
    now = time.time()
    sps = (step - self.step_last) / max(now - self.t_last, 1e-9)
    self.t_last, self.step_last = now, step
    row = {
      "step": step,
      "train_loss": loss,
      **{k: float(v) for k, v in metrics.items() if k != "loss"},
      "steps_per_s": sps,
    }
    if val_loss is not None:
      row["val_loss"] = val_loss
    with open(self.path, "a") as f:
      f.write(json.dumps(row) + "\n")
    if self.writer is not None:
      for k, v in row.items():
        if k != "step":
          self.writer.add_scalar(("val/" if k == "val_loss" else "train/") + k.removeprefix("train_"), v, step)
    self.progress.update(step, row, (self.total - step) / max(sps, 1e-9))

  def close(self) -> None:
    self.progress.close()
    if self.writer is not None:
      self.writer.close()


def evaluation_hook(val, loss_fn: Callable):
  """Measures the validation loss (``loop.val_loss``: ``loss_fn(params, val)``) and publishes it with the
  step's metrics."""

  def evaluate(loop: Loop) -> None:
    if val:
      loop.val_loss = float(loss_fn(loop.state["params"], val))
    loop.flush()

  return evaluate


def patience_hook(patience: int, save: Callable[[Loop], None], say: Callable[[str], None]):
  """``train.patience``: ends training (``loop.ended``, with a checkpoint of the step) once ``patience``
  validation passes in a row have not lowered the validation loss."""
  best, since = [math.inf, 0], [0]

  def check(loop: Loop) -> None:
    if loop.val_loss is None:
      return
    if loop.val_loss < best[0]:
      best[:], since[0] = [loop.val_loss, loop.step], 0
      return
    since[0] += 1
    if since[0] >= patience:
      loop.ended = (
        f"ended at step {loop.step}: {patience} validation passes without a lower loss (train.patience; the "
        f"lowest, {best[0]:.4g}, at step {best[1]})"
      )
      say(loop.ended)
      save(loop)

  return check


def checkpoint_hook(manager, meta_of: Callable[[int], dict]):
  """Saves the state once the step's loss is known to be finite (``meta_of(step)`` is its meta)."""

  def save(loop: Loop) -> None:
    loop.flush()
    ckpt.save(manager, loop.step, loop.state, meta_of(loop.step), loop.val_loss)
    loop.last_good = loop.step

  return save


def best_checkpoint_hook(manager, save: Callable, val_loss: Callable[[Loop], float | None] = lambda l: l.val_loss):
  """``train.keep = "best"``: a checkpoint at every evaluation whose validation loss (``val_loss(loop)``; a
  vectorized run's point reads its own) is the lowest so far, counting the steps kept before a resume (the
  manager keeps the best by validation loss beside the latest ones)."""
  best = [min(ckpt.val_losses(manager).values(), default=math.inf)]

  def save_if_best(loop: Loop) -> None:
    val = val_loss(loop)
    if val is not None and val < best[0]:
      best[0] = val
      if manager.latest_step() != loop.step:
        save(loop)

  return save_if_best


def figure_hook(writer, graphdef, host_params, ds: Dataset, cfg: Config):
  """A short generated sample beside a real one, as a TensorBoard figure (needs matplotlib)."""
  try:
    plt = require_matplotlib()
  except UserError:
    return lambda loop: None

  def draw(loop: Loop) -> None:
    n, s, sk = 120, cfg.sample, ds.features.skeleton
    real_id, real_z = (ds.val or ds.train)[0]
    key = jax.random.key(loop.step)
    params, controls = host_params(loop.state["params"]), Controls.resolve(s)
    features = with_ceiling(ds.features, graphdef, params, ds.train, cfg.data.seq_length, controls)
    gen = family_of(cfg).dance(graphdef, params, features, np.array([real_id]), key, n, controls)
    fig, axes = plt.subplots(1, 2, figsize=(10, 3), sharey=True)
    real = np.asarray(ds.features.decode(real_z[:n]))
    for ax, pos_TxJx3, title in ((axes[0], real, "real"), (axes[1], gen[0], "generated")):  # drawn as samples are
      for j in sk.end_joints:
        ax.plot(pos_TxJx3[:, j, 1], lw=1, label=sk.joint_names[j])
      ax.set_title(f"{title}: end joints, vertical axis")
    axes[0].legend(fontsize=6)
    writer.add_figure("sample/end_joints", fig, loop.step)
    plt.close(fig)

  return draw
