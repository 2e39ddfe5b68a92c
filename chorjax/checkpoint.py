"""Orbax checkpoints that hold everything a run needs to resume and to sample.

Each checkpoint step has three items:
  ``params``: the model parameters, on their own, so sampling and evaluation restore them without
  building an optimizer (as big_vision loads params);
  ``train``: ``{opt_state, step}``, what resuming needs besides the params;
  ``meta``: JSON with the resolved config, the feature pipeline (normalization statistics,
  representation, skeleton), the motion-id map, the RNG seed and the data-sampler position;
and, where the step was evaluated, orbax's own ``metrics`` (its validation loss, so that a resumed run's
manager still knows which step is the best).
Runs written before 2026-11-22 hold one ``state`` item ``{params, opt_state, step}`` instead; they
restore the same way (their params alone by a partial restore).
The manager keeps the latest ``keep`` steps plus the best one by validation loss.
"""

from __future__ import annotations

import contextlib
import json
import logging
import re
import shutil
import time
import warnings
from pathlib import Path

import jax
import orbax.checkpoint as ocp
from orbax.checkpoint.checkpoint_managers import preservation_policy as pp

from chorjax.errors import UserError, load_json, whole_number


class _ReadOnlyNotice(logging.Filter):
  """Drops orbax's warning that a directory opened read-only is read-only (we asked for that), that a step
  was saved without a validation loss (a run with no validation takes: the latest steps are kept), and its
  background threads' tracebacks of a failed write (``wait`` reports that failure as one line)."""

  def filter(self, record: logging.LogRecord) -> bool:
    msg = str(record.msg)
    failed_write = "orbax" in record.pathname and record.levelno >= logging.ERROR  # re-raised by `wait`/`save`
    expected = msg.startswith(("Given directory is read only", "Requested `tracked_metric`"))
    return not (expected or failed_write)


logging.getLogger("absl").addFilter(_ReadOnlyNotice())


def checkpoint_dir(workdir) -> Path:
  return Path(workdir).absolute() / "checkpoints"


def _val_loss(metrics) -> float:
  return metrics["val_loss"]


def _write_missing_metrics(directory: Path) -> None:
  """Steps saved before orbax wrote their metrics (chorjax before 2026-11-27) get them from their own meta,
  so that resuming such a run keeps its best step. A step whose meta cannot be read is left as it is."""
  if not directory.is_dir():
    return
  for step in directory.iterdir():
    metrics = step / "metrics" / "metrics"
    if not step.name.isdigit() or metrics.exists() or not (step / "commit_success.txt").exists():
      continue
    try:
      val_loss = load_json((step / "meta" / "metadata").read_text()).get("val_loss")
    except (OSError, ValueError, AttributeError):
      continue
    if isinstance(val_loss, (int, float)):
      with contextlib.suppress(OSError):  # not writable: saving will say so, in one line
        metrics.parent.mkdir(exist_ok=True)
        metrics.write_text(json.dumps({"val_loss": float(val_loss)}))


def create_manager(workdir, keep: int = 3, read_only: bool = False) -> ocp.CheckpointManager:
  if not read_only:
    _write_missing_metrics(checkpoint_dir(workdir))
  policy = pp.AnyPreservationPolicy(
    [pp.LatestN(keep), pp.BestN(get_metric_fn=_val_loss, reverse=True, n=1, keep_checkpoints_without_metrics=False)]
  )
  options = ocp.CheckpointManagerOptions(
    preservation_policy=policy,
    # best_fn makes orbax write each step's metrics beside it: without them a reopened manager (a resumed
    # run) knew no step's validation loss, and BestN deleted the best step at the first save after resuming
    best_fn=_val_loss,
    best_mode="min",
    cleanup_tmp_directories=not read_only,
    create=not read_only,
    read_only=read_only,
    save_interval_steps=0 if read_only else 1,  # (orbax warns when it has to set this itself)
    # Synchronous: a failed write (disk full, read-only) is then one error at its step. Written in the
    # background it surfaced later, after orbax's threads had printed hundreds of lines of tracebacks
    # from a closed event loop. A save of the quickstart takes well under a second.
    enable_async_checkpointing=False,
  )
  return ocp.CheckpointManager(checkpoint_dir(workdir), options=options)


def save(manager: ocp.CheckpointManager, step: int, state, meta: dict, val_loss: float | None) -> None:
  """Saves ``state = {params, opt_state, step}`` and ``meta`` (synchronously; a failed write is a
  one-line UserError and leaves no partial step behind)."""
  metrics = {"val_loss": float(val_loss)} if val_loss is not None else None
  meta = {**meta, "val_loss": metrics and metrics["val_loss"]}
  train = {"opt_state": state["opt_state"], "step": state["step"]}
  with _writing(manager, step):
    manager.save(
      step,
      args=ocp.args.Composite(
        params=ocp.args.StandardSave(state["params"]), train=ocp.args.StandardSave(train), meta=ocp.args.JsonSave(meta)
      ),
      metrics=metrics,
    )


def wait(manager: ocp.CheckpointManager) -> None:
  """Waits for any pending save (saves are synchronous, see ``create_manager``; this also finalizes
  orbax's bookkeeping); a write that failed is a one-line UserError and its partial files are removed."""
  with _writing(manager, None):
    manager.wait_until_finished()


def close_quietly(manager: ocp.CheckpointManager) -> None:
  """Waits and closes on the way out of an error (the error that is already on its way is the one to
  report); on success paths :func:`wait` has run before."""
  _quiet_abandoned_writes()
  with contextlib.suppress(Exception):
    manager.wait_until_finished()
  with contextlib.suppress(Exception):
    manager.close()
  _remove_partial(manager)


@contextlib.contextmanager
def _writing(manager, step: int | None):
  try:
    yield
  except Exception as e:  # orbax and tensorstore surface a failed write in several types
    _remove_partial(manager)
    _quiet_abandoned_writes()
    text = str(e)
    known = (
      "No space left on device",
      "Read-only file system",
      "Permission denied",
      "Disk quota exceeded",
      "File too large",
    )
    reason = next((k for k in known if k in text), _first_line(e))
    at = f" at step {step}" if step is not None else ""
    raise UserError(f"{manager.directory}: the checkpoint{at} could not be written ({reason})") from None


def _quiet_abandoned_writes() -> None:
  """After a failed write, orbax's unfinished write coroutines are collected un-awaited, some only at exit,
  and Python warns of each on stderr ("coroutine 'async_serialize_from_host.<locals>.write_fragment' was
  never awaited"). The failure reaches the user as one line (a UserError), so those warnings are dropped:
  only for orbax's coroutines, and only once a write has failed or a run is closing on an error."""
  warnings.filterwarnings(
    "ignore", message=r"coroutine '.*(serialize|write).*' was never awaited", category=RuntimeWarning
  )


def _remove_partial(manager) -> None:
  """Removes a failed write's temporary step (its writer threads may still be finishing: retried)."""
  for _ in range(20):
    left = list(Path(manager.directory).glob("*.orbax-checkpoint-tmp*"))
    if not left:
      return
    for tmp in left:
      shutil.rmtree(tmp, ignore_errors=True)
    time.sleep(0.1)


def _is_legacy(manager: ocp.CheckpointManager, step: int) -> bool:
  """A checkpoint written before params had their own item (one ``state`` item)."""
  return (Path(manager.directory) / str(step) / "state").is_dir()


def _abstract(template, sharding=None):
  if sharding is None:
    return jax.tree.map(ocp.utils.to_shape_dtype_struct, template)
  return jax.tree.map(lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=sharding), template)


def _first_line(e: Exception) -> str:
  return (str(e).strip().splitlines() or [type(e).__name__])[0][:160]


def _mismatch(manager, step, e: Exception) -> UserError:
  return UserError(f"{manager.directory}/{step}: checkpoint does not match this model config ({_first_line(e)})")


class Damaged(UserError):
  """A checkpoint step whose files cannot be read back (truncated, emptied or missing); ``step`` says which."""

  def __init__(self, message: str, step: int):
    super().__init__(message)
    self.step = step


def _damaged(manager, step: int, item: str, e: Exception) -> Damaged:
  """Names the file when the storage layer's message does (it usually does), else the item's folder."""
  where = Path(manager.directory) / str(step) / item
  named = [w.strip("'\",:;()[]") for w in str(e).split() if str(where) in w]
  shapes = re.search(r"Requested shape: (\([^)]*\)).*stored shape: (\([^)]*\))", str(e))
  if shapes:  # the files are whole, but not of the model the step's meta describes (an edited meta, mixed runs)
    why = (
      f"its parameters do not fit the model its meta describes: an array of shape {shapes[2]} where {shapes[1]} is due"
    )
  else:
    why = f"{type(e).__name__}: {_first_line(e)}"
  return Damaged(f"{named[0] if named else where}: damaged checkpoint ({why})", step)


def step_meta(manager, step) -> dict:
  """The JSON meta of one checkpoint step (config, features, id map, ...).

  Raises:
    Damaged: its meta file is missing, empty or not JSON.
  """
  try:
    meta = manager.restore(step, args=ocp.args.Composite(meta=ocp.args.JsonRestore()))["meta"]
  except Exception as e:  # orbax and tensorstore raise many types for one cause: bad files
    raise _damaged(manager, step, "meta/metadata", e) from None
  if not isinstance(meta, dict):
    raise Damaged(f"{manager.directory}/{step}/meta/metadata: damaged checkpoint (not a JSON object)", step)
  return dict(meta)


def val_losses(manager) -> dict[int, float]:
  """``{step: validation loss}`` of the kept intact steps that have one."""
  losses = {}
  for s in manager.all_steps():
    with contextlib.suppress(Damaged):
      losses[s] = step_meta(manager, s).get("val_loss")
  return {s: v for s, v in losses.items() if v is not None}


def best_step(manager) -> int | None:
  """The kept step with the lowest validation loss (None if no intact checkpoint has one)."""
  losses = val_losses(manager)
  return min(losses, key=losses.__getitem__) if losses else None


def move_aside(manager: ocp.CheckpointManager, steps) -> Path:
  """Moves damaged steps into ``checkpoints-damaged/`` beside the checkpoints (nothing is deleted) and
  lets the manager forget them; returns that folder."""
  d = Path(manager.directory)
  aside = d.parent / "checkpoints-damaged"
  aside.mkdir(exist_ok=True)
  for step in steps:
    target = aside / str(step)
    k = 1
    while target.exists():
      target, k = aside / f"{step}.{k}", k + 1
    shutil.move(str(d / str(step)), str(target))
  manager.reload()
  return aside


def restore(manager: ocp.CheckpointManager, step: int, template, sharding=None, mismatch: bool = False):
  """Restores ``{params, opt_state, step}`` of ``step`` into the structure of ``template`` (to resume).

  With ``sharding`` every array is restored with it (e.g. replicated over the current mesh), so a
  checkpoint written by one process count resumes on another.

  Raises:
    UserError: the checkpoint cannot be restored: with ``mismatch`` (the caller knows the model config
      changed) as a config mismatch, otherwise as ``Damaged``.
  """
  abstract = _abstract(template, sharding)
  try:
    if _is_legacy(manager, step):
      state = manager.restore(step, args=ocp.args.Composite(state=ocp.args.StandardRestore(abstract)))["state"]
    else:
      train = {"opt_state": abstract["opt_state"], "step": abstract["step"]}
      r = manager.restore(
        step,
        args=ocp.args.Composite(
          params=ocp.args.StandardRestore(abstract["params"]), train=ocp.args.StandardRestore(train)
        ),
      )
      state = {"params": r["params"], **r["train"]}
  except Exception as e:  # bad files and a changed model both surface here, in many types
    raise (_mismatch(manager, step, e) if mismatch else _damaged(manager, step, "", e)) from None
  # Re-impose the template's tree (optax states are namedtuples; keep their types exactly).
  return jax.tree.unflatten(jax.tree.structure(template), jax.tree.leaves(state))


def restore_params(manager: ocp.CheckpointManager, step: int, template):
  """Restores only the params of ``step`` into the structure of ``template`` (no optimizer needed; the
  template is built from the step's own config, so a failure means damaged files: ``Damaged``)."""
  abstract = _abstract(template, jax.sharding.SingleDeviceSharding(jax.devices()[0]))
  try:
    if _is_legacy(manager, step):  # a partial restore of the old single ``state`` item
      item = {"params": abstract}
      args = ocp.args.PyTreeRestore(
        item=item, restore_args=ocp.checkpoint_utils.construct_restore_args(item), partial_restore=True
      )
      params = manager.restore(step, args=ocp.args.Composite(state=args))["state"]["params"]
    else:
      params = manager.restore(step, args=ocp.args.Composite(params=ocp.args.StandardRestore(abstract)))["params"]
  except Exception as e:  # the template comes from the step's own config: a failure is bad files
    raise _damaged(manager, step, "params", e) from None
  return jax.tree.unflatten(jax.tree.structure(template), jax.tree.leaves(params))


def open_run(workdir) -> ocp.CheckpointManager:
  """A read-only manager over a run's checkpoints (close it after use)."""
  d = checkpoint_dir(workdir)
  if not d.is_dir():
    raise UserError(f"{workdir}: no checkpoints (expected {d}); train first with `chorjax train`")
  return create_manager(workdir, read_only=True)


def resolve_step(manager, which, workdir) -> int:
  steps = manager.all_steps()
  if not steps:
    raise UserError(f"{workdir}: no finished checkpoints in {checkpoint_dir(workdir)}")
  if which == "latest":
    return manager.latest_step()
  if which == "best":
    best = best_step(manager)
    if best is None:
      raise UserError(f"{workdir}: no checkpoint has a validation loss (no held-out takes?); use latest")
    return best
  try:
    if isinstance(which, bool) or not isinstance(which, int | str):
      raise ValueError(which)
    step = whole_number(str(which))
  except ValueError:
    raise UserError(f"--checkpoint {str(which)[:40]!r}: expected a step number, 'kept', 'latest' or 'best'") from None
  if step not in steps:
    raise UserError(f"{workdir}: no checkpoint at step {step}; available: {', '.join(map(str, sorted(steps)))}")
  return step
