"""Training: a loop driven by hooks, and the driver ``train_and_evaluate`` that runs a family's step in it.

The state is a plain pytree ``{params, opt_state, step}`` that the run's family (``chorjax.families``)
builds, with its jitted step, batch sampler and validation loss. Randomness comes from
``fold_in(key(seed), step)`` and batches from the sampler's ``batch(step)``, so a run resumed from a
checkpoint at step s repeats exactly what the uninterrupted run did after s.

The loop and its hooks are ``chorjax.training.loop``'s; this module keeps the run directory (its lock, the saved
config, what a resume reads back) and the driver that puts a family's step, hooks and end-of-run sample
together.
"""

from __future__ import annotations

import contextlib
import dataclasses
import fcntl
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import jax

from chorjax import checkpoint as ckpt
from chorjax.config import Config, config_diff, config_from_dict, resumable_keys
from chorjax.data.dataset import Dataset, dataset_notes, load_dataset
from chorjax.errors import UserError, atomic_write, is_run_folder, load_json
from chorjax.families import family_of
from chorjax.models import motion_weight_vector
from chorjax.run import run_meta
from chorjax.training import end_of_run
from chorjax.training.loop import (
  Loop,
  MetricsLog,
  agreed_stop,
  best_checkpoint_hook,
  checkpoint_hook,
  evaluation_hook,
  figure_hook,
  patience_hook,
  stop_on_signals,
)

# ---------------------------------------------------------------- run directory


def default_workdir(cfg: Config) -> Path:
  return Path("runs") / cfg.name


@contextlib.contextmanager
def workdir_lock(workdir: Path):
  """An exclusive lock on the workdir; the OS releases it even if the process is killed."""
  workdir.mkdir(parents=True, exist_ok=True)
  f = open(workdir / ".lock", "a+")  # noqa: SIM115 - held open while the run holds the lock
  try:
    fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
  except BlockingIOError:
    f.close()
    raise UserError(f"{workdir}: in use by another `chorjax train` (lock {workdir / '.lock'})") from None
  try:
    yield
  finally:
    fcntl.flock(f, fcntl.LOCK_UN)
    f.close()


def _check_saved_config(workdir: Path, cfg: Config, force: bool) -> bool:
  """Refuses a workdir whose saved config differs, unless ``force``; returns whether the saved config
  differs (or is unreadable) and must be kept aside once the new run has started (:func:`_keep_aside`)."""
  path = workdir / "config.json"
  if not path.exists():
    return False
  try:
    saved = config_from_dict(load_json(path.read_text()))
  except (json.JSONDecodeError, UserError) as e:
    if not force:
      raise UserError(f"{path}: unreadable saved config ({e}); use --force to replace it") from None
    return True
  diff = config_diff(saved, cfg, ignore=resumable_keys())
  if diff and not force:
    raise UserError(
      f"{workdir}: holds a run with a different config ({'; '.join(diff[:3])}"
      f"{' ...' if len(diff) > 3 else ''}); use another --workdir, or --force to continue it"
    )
  return bool(diff)


def _keep_aside(workdir: Path) -> None:
  """The old config.json copied to config.<time>.json before the new one replaces it: nothing is
  overwritten silently, and nothing is moved before the new run has restored (a failed --force leaves
  the workdir as it was)."""
  old = workdir / "config.json"
  atomic_write(workdir / f"config.{int(time.time())}.json", lambda p: p.write_bytes(old.read_bytes()))


def _write_config(workdir: Path, cfg: Config) -> None:
  atomic_write(workdir / "config.json", lambda p: p.write_text(json.dumps(cfg.to_dict(), indent=2)))


def _truncate_metrics(path: Path, upto_step: int) -> None:
  """Drops rows logged after the checkpoint we resume from (a killed run may have written them)."""
  if not path.exists():
    return
  rows = [l for l in path.read_text(errors="replace").splitlines() if l.strip()]
  parsed = [metrics_row(l) for l in rows]
  torn = [k for k, r in enumerate(parsed) if r is None]
  if torn:  # what a kill mid-write leaves: a half-written line (normally the last)
    print(f"note: {path}: dropped {len(torn)} unreadable line(s) (first: line {torn[0] + 1}, a write cut short)")
  kept = [l for l, r in zip(rows, parsed) if r is not None and r.get("step", 0) <= upto_step]
  if len(kept) != len(rows):
    atomic_write(path, lambda p: p.write_text("".join(l + "\n" for l in kept)))


def metrics_row(line: str) -> dict | None:
  """One ``metrics.jsonl`` row, or None where it is not one (torn by a kill)."""
  try:
    row = load_json(line)
  except json.JSONDecodeError:
    return None
  return row if isinstance(row, dict) else None


MAX_STEPS = 2**31  # train.num_steps and what train.epochs resolves to stay below it: the step counter is int32


def sized_to_data(cfg: Config, ds: Dataset) -> tuple[Config, str | None]:
  """``train.epochs``: the config with ``train.num_steps`` set from the training frames, and a line saying so."""
  t = cfg.train
  if t.epochs <= 0:
    return cfg, None
  frames = sum(len(x) for _, x in ds.train)
  exact = t.epochs * frames / (t.batch_size * cfg.data.seq_length)
  if not exact < MAX_STEPS:  # the step counter is a 32-bit integer (and inf or NaN is no count)
    raise UserError(
      f"train.epochs = {t.epochs:g}: {exact:,.0f} steps over {frames:,} training frames; at most {MAX_STEPS - 1:,}"
    )
  steps = max(1, math.ceil(exact))
  line = (
    f"train.epochs = {t.epochs:g}: {steps:,} steps ({frames:,} training frames, augmentations included, in "
    f"windows of {t.batch_size} x {cfg.data.seq_length})"
  )
  return dataclasses.replace(cfg, train=dataclasses.replace(t, num_steps=steps)), line


# ---------------------------------------------------------------- the driver


def train_and_evaluate(cfg: Config, workdir, *, force: bool = False, parallel=None, finish=None) -> dict:
  """Trains ``cfg`` in ``workdir``, resuming from its latest checkpoint; returns a summary.

  ``finish``: hooks the main process runs once the run has trained all its steps (not when stopped), each
  ``hook(end_of_run.Finished) -> dict`` of what it wrote (the summary's ``samples``); default
  ``end_of_run.standard(cfg)``: calibration and the sample drawn with it (``train.calibrate``), else the
  end sample.

  Writes ``config.json``, ``metrics.jsonl``, TensorBoard events, ``checkpoints/`` and, at the end,
  ``samples/`` (a short sample and its HTML player). With ``parallel`` (see ``chorjax.training.parallel``)
  every process trains its share and only process 0 writes anything but checkpoints.
  """
  workdir = Path(workdir).absolute()
  check_workdir(workdir, force)
  family = family_of(cfg)
  family.check(cfg)  # before anything is written
  if parallel is not None and not family.data_parallel:
    name = family.name
    raise UserError(f"parallel.data_parallel: not available for the {name} family (model.family = {name!r})")
  is_main = parallel is None or parallel.is_main
  before = {p.name for p in workdir.iterdir()} if workdir.is_dir() else None
  try:
    return _locked_train(cfg, workdir, force, parallel, is_main, finish)
  except UserError:
    if is_main:
      _clean_refused_start(workdir, before)
    raise


def _clean_refused_start(workdir: Path, before: set | None) -> None:
  """A start refused before any step ran leaves what it found: its own lock, an empty checkpoints/ and a
  workdir it created go again (``before``: the names the workdir held, None where it did not exist)."""
  left = {p.name for p in workdir.iterdir()} if workdir.is_dir() else set()
  if left - (before or set()) - {".lock", "checkpoints"}:
    return  # something else was written: a run that got further keeps its files
  ckpts = workdir / "checkpoints"
  if "checkpoints" not in (before or set()) and ckpts.is_dir() and not any(ckpts.iterdir()):
    ckpts.rmdir()
  if ".lock" not in (before or set()):
    (workdir / ".lock").unlink(missing_ok=True)
  if before is None and workdir.is_dir() and not any(workdir.iterdir()):
    workdir.rmdir()


def _locked_train(cfg: Config, workdir: Path, force: bool, parallel, is_main: bool, finish) -> dict:
  with workdir_lock(workdir) if is_main else contextlib.nullcontext():
    keep_old_config = _check_saved_config(workdir, cfg, force) and is_main
    ds = load_dataset(cfg.data)
    cfg, budget = sized_to_data(cfg, ds)
    if is_main:
      for line in [*dataset_notes(ds), *([budget] if budget else [])]:
        print(line, file=sys.stderr if line.startswith("warning") else sys.stdout, flush=True)
    if cfg.sample.frames > 0:  # fail now, not after hours of training, if the end sample cannot be drawn
      motion_weight_vector(len(ds.motions), cfg.sample.motion, source="sample.motion =")
    manager = ckpt.create_manager(workdir, keep=cfg.train.keep_checkpoints)
    with contextlib.ExitStack() as cleanup:
      cleanup.callback(ckpt.close_quietly, manager)
      return _train(cfg, workdir, ds, manager, parallel, cleanup, keep_old_config, finish)


def check_workdir(workdir: Path, force: bool) -> None:
  """Refuses a ``workdir`` that is a file, or a folder of other files than a run's (unless ``force``):
  training would write among them."""
  if workdir.exists() and not workdir.is_dir():
    raise UserError(f"{workdir}: is a file, not a run directory (--workdir names a folder)")
  if workdir.is_dir() and not force and not _is_run(workdir):
    raise UserError(
      f"{workdir}: holds files and is not a chorjax run (no config.json or checkpoints/); training would "
      "write into it: choose another --workdir, or --force"
    )


def _is_run(workdir: Path) -> bool:
  """Whether a folder is a run (or still empty but for a lock a refused start left)."""
  return is_run_folder(workdir) or {p.name for p in workdir.iterdir()} <= {".lock"}


def _restore_or_init(cfg: Config, workdir: Path, ds: Dataset, manager, parallel) -> tuple[dict, Any, int]:
  """The newest intact checkpoint's state (checked to be of these takes), or a fresh one if there is none.

  A damaged checkpoint (a killed write, a truncated file) is moved aside into ``checkpoints-damaged/``
  with a warning line and the next older one is tried; if every one is damaged, a UserError (never a
  silent restart from step 0)."""
  state, spec = family_of(cfg).create_state(cfg, ds)
  steps = sorted(manager.all_steps(), reverse=True)
  damaged = []
  for start in steps:
    try:
      meta = ckpt.step_meta(manager, start)
      if meta["id_map"] != ds.id_map:
        raise UserError(f"{workdir}: its checkpoints were trained on other takes ({list(meta['id_map'])[:3]}...)")
      saved = config_from_dict(meta["config"])
      changed = saved.model_sections() != cfg.model_sections()
      sharding = None if parallel is None else parallel.replicated
      restored = ckpt.restore(manager, start, state, sharding, mismatch=changed)
    except ckpt.Damaged as e:
      damaged.append(e)
      continue
    if damaged and (parallel is None or parallel.is_main):
      aside = ckpt.move_aside(manager, [e.step for e in damaged])
      print(f"warning: {damaged[0]}; moved to {aside}, resuming from step {start}", file=sys.stderr)
    return restored, spec, start
  if damaged:
    raise UserError(
      f"{damaged[0]}; no intact checkpoint in {ckpt.checkpoint_dir(workdir)} (move it aside to start over)"
    )
  return state, spec, 0


def _train(
  cfg: Config, workdir: Path, ds: Dataset, manager, parallel, cleanup: contextlib.ExitStack, keep_old_config, finish
) -> dict:
  t_start = time.time()
  is_main = parallel is None or parallel.is_main
  state, spec, start = _restore_or_init(cfg, workdir, ds, manager, parallel)
  if keep_old_config:
    _keep_aside(workdir)
  if is_main:
    _write_config(workdir, cfg)
    _truncate_metrics(workdir / "metrics.jsonl", start)
  family = family_of(cfg)
  jitted, sampler, val, val_loss = family.parts(cfg, ds)
  key: Any = jax.random.key(cfg.train.seed)
  get_batch, host_params = sampler.batch, lambda p: p
  if parallel is not None:
    state, val, key = parallel.replicate(state), parallel.replicate(val), parallel.replicate(jax.random.key_data(key))
    jitted = family.parallel_step(parallel)
    get_batch, host_params = (lambda s: parallel.global_batch(sampler, s)), parallel.local_copy
  step_fn = lambda state, batch, key: jitted(state, batch, key, spec)
  total = cfg.train.num_steps
  loop = Loop(step_fn, get_batch, key, state, start, total)
  log = None
  if is_main:
    log = MetricsLog(workdir, cfg, start)
    cleanup.callback(log.close)
    loop.listeners.append(log)
  meta_of = lambda step: run_meta(cfg, ds.features, step, ds)
  loop.add_hook(evaluation_hook(val, lambda params, val: val_loss(params, val, spec)), cfg.train.eval_every)
  save = checkpoint_hook(manager, meta_of)
  loop.add_hook(save, cfg.train.checkpoint_every)
  if cfg.train.keep == "best" and val:  # the best is kept where it happens, not at the next checkpoint_every
    loop.add_hook(best_checkpoint_hook(manager, save), cfg.train.eval_every or total)
  if cfg.train.patience:
    if not (val and cfg.train.eval_every):
      raise UserError("train.patience: needs validation passes (train.eval_every > 0) and held-out takes")
    say = (lambda line: print(line, flush=True)) if is_main else (lambda line: None)
    loop.add_hook(patience_hook(cfg.train.patience, lambda loop: save_now(loop), say), cfg.train.eval_every)
  if log is not None and log.writer is not None and cfg.train.figure_every and family.figures:
    loop.add_hook(figure_hook(log.writer, spec.graphdef, host_params, ds, cfg), cfg.train.figure_every, at_last=False)
  loop.end_hooks.append(lambda loop: ckpt.wait(manager))

  def save_now(loop: Loop) -> None:  # on SIGINT/SIGTERM: this step's checkpoint, unless just written
    if manager.latest_step() != loop.step:
      save(loop)
    ckpt.wait(manager)

  loop.on_stop = save_now
  with stop_on_signals() as stop:
    loop.stop = stop if parallel is None else agreed_stop(stop)
    loop.run()
  samples: dict = {}
  if is_main and total > 0 and (loop.step >= total or loop.ended):  # finished, not stopped
    finished = end_of_run.Finished(workdir, ds, cfg, spec.graphdef, host_params(loop.state["params"]))
    for hook in end_of_run.standard(cfg) if finish is None else finish:
      samples.update(hook(finished))
  summary = _summary(loop, start, time.time() - t_start, samples)
  if cfg.train.keep == "best" and val and is_main:  # what sample, eval and export will use
    summary |= _kept(manager)
  return summary


def _summary(loop: Loop, start: int, seconds: float, samples: dict) -> dict:
  """What training returns: steps, losses, time, and the end samples written."""
  summary = {
    "start_step": start,
    "final_step": loop.step,
    "train_losses": loop.losses,
    "seconds": seconds,
    "compile_s": loop.compile_s,
  }
  if loop.losses:
    summary["final_train_loss"] = loop.losses[max(loop.losses)]
  if loop.val_loss is not None:
    summary["final_val_loss"] = loop.val_loss
  return summary | ({"samples": samples} if samples else {})


def _kept(manager) -> dict:
  """``train.keep = "best"``: the kept step and its validation loss (none without one)."""
  kept = ckpt.val_losses(manager)
  if not kept:
    return {}
  step = min(kept, key=kept.__getitem__)
  return {"kept_step": step, "kept_val_loss": kept[step]}
