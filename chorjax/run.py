"""A run: the meta saved with every checkpoint, and a run directory loaded back.

Training and sampling both stand on this module and it imports neither: data -> models -> families ->
run -> train, sample -> cli.

* :func:`run_meta` is the JSON that every checkpoint carries (config, features, motion ids, takes).
* :func:`load_run` reads a run directory back as a typed :class:`Run` with its params restored on
  their own (no optimizer is built), for sampling and evaluation; its model is built by the run's
  family (``chorjax.families``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from flax import nnx

from chorjax import checkpoint as ckpt
from chorjax.config import Config, config_from_dict
from chorjax.data.dataset import conform, load_dataset, read_takes, with_tails
from chorjax.data.features import Features
from chorjax.data.labels import Labels, take_condition
from chorjax.errors import UserError, atomic_write, check_draw, load_json
from chorjax.families import family_of
from chorjax.models import motion_weight_vector
from chorjax.sampling.calibration_file import read_calibration
from chorjax.sampling.controls import Controls, with_ceiling

if TYPE_CHECKING:  # (the annotation only: a family reads runs back)
  from chorjax.families.family import Family


def model_template(cfg: Config, features: Features, num_motions: int) -> tuple[Any, dict]:
  """``(graphdef, abstract params)`` of ``cfg``'s model (any family), without computing any parameter."""
  model = nnx.eval_shape(lambda: family_of(cfg).build_model(cfg, features, num_motions))
  graphdef, params = nnx.split(model, nnx.Param)
  return graphdef, nnx.to_pure_dict(params)


def run_meta(cfg: Config, features: Features, step: int, ds) -> dict:
  """The JSON meta every checkpoint carries: what sampling needs, what resuming checks, the frame rate
  of the training takes, and how each mapped take was put on the 16-joint layout (``joint_maps``)."""
  return {
    "config": cfg.to_dict(),
    "features": features.to_dict(),
    "id_map": ds.id_map,
    "train_takes": list(ds.train_names),
    "val_takes": list(ds.val_names),
    "fps": ds.fps,
    "rng": {"seed": cfg.train.seed, "fold_in": "step"},
    "sampler": {"seed": cfg.train.seed, "position": step},
    "step": step,
    "joint_maps": {name: m.to_dict() for name, m in ds.mappings.items()},
    "labels": None if ds.labels is None else ds.labels.to_dict(),
  }


@dataclasses.dataclass(frozen=True)
class Run:
  """A trained run loaded from its directory.

  Attributes:
    workdir: the run directory.
    config: the run's resolved config.
    features: the fitted feature pipeline (data space <-> model features).
    id_map: what conditions the model -> its index: take names, or ``field=value`` with ``labels``.
    train_takes, val_takes: the split it was trained on.
    graphdef, params: the model (``nnx.merge(graphdef, params)``).
    step: the checkpoint's step.
    val_loss: the validation loss saved with that checkpoint (None without held-out takes).
    joint_maps: take name -> how it was mapped onto the 16-joint layout (``Mapping.to_dict()``).
    labels: the named labels the run is conditioned on (``data.labels``), or None (one id per take).
  """

  workdir: Path
  config: Config
  features: Features
  id_map: dict
  train_takes: tuple
  val_takes: tuple
  graphdef: Any
  params: dict
  step: int
  val_loss: float | None
  joint_maps: dict = dataclasses.field(default_factory=dict)
  frame_rate: float | None = None
  labels: Labels | None = None

  def __repr__(self) -> str:
    m = self.config.model
    loss = "" if self.val_loss is None else f", val loss {self.val_loss:.4g}"
    return (
      f"{type(self).__name__}({str(self.workdir)!r}: {m.family} {m.cell} {m.num_layers}x{m.hidden_size} {m.head}, "
      f"step {self.step:,}{loss}, {len(self.train_takes)} training takes, {self.features.dim} features)"
    )

  @property
  def num_motions(self) -> int:
    return len(self.id_map)

  def motion_weights(self, motion=None, mix=None, source: str = "--motion") -> np.ndarray:
    """The weights ``[M]`` that condition a dance: a take id or ``ID:W,...`` blend, or with labels
    ``FIELD=VALUE,...`` or ``FIELD=VALUE:W,...`` (nothing given: take 0, or each label's first value)."""
    if self.labels is not None:
      return self.labels.parse(motion, mix, source)
    if isinstance(motion, str):
      try:
        motion = int(motion)
      except ValueError:
        raise UserError(
          f"{source} {motion!r}: this run is conditioned on take ids (0..{self.num_motions - 1})"
        ) from None
    return motion_weight_vector(self.num_motions, motion, mix, source)

  def take_condition(self, name: str, default: int | None = 0):
    """What conditions the model on the take ``name`` (``labels.take_condition``): its id (``default`` for a
    take the run never read), or with labels the weights of its labels."""
    return take_condition(self.labels, self.id_map, name, default)

  def dancer_conditions(self, takes, num: int) -> np.ndarray:
    """``[num]`` ids or ``[num, M]`` weights: dancer k conditioned on the k-th of ``takes`` (cycled; none:
    take 0, or each label's first value). With labels and more takes than dancers, the dancers' takes are
    spread evenly over ``takes`` instead: a library's names sort by label, so its first few are one action."""
    conds = [self.take_condition(m.name) for m in takes] or [self.motion_weights() if self.labels else 0]
    if self.labels is not None and len(conds) > num:
      return np.array([conds[(k * len(conds)) // num] for k in range(num)])
    return np.array([conds[k % len(conds)] for k in range(num)])

  @property
  def fps(self) -> float:
    """The frame rate of the training takes (runs from before it was recorded: ``data.fps``)."""
    return self.frame_rate or self.config.data.fps

  @property
  def family(self) -> Family:
    """The run's model family (``model.family``)."""
    return family_of(self.config)

  def serving(self, command: str) -> Run:
    """This run, for ``command`` (``sample``, ``eval``, ``calibrate``, ``live``, ``inbetween``): a UserError
    where its family cannot serve it (an in-betweening run writes no dance of its own, ...)."""
    why = self.family.refusal(command)
    if why is not None:
      raise UserError(f"{self.workdir}: {why}")
    return self

  def sampling(self, use_calibration: bool = True, **given) -> Controls:
    """Sampling controls: the ones given (not None), else the run's calibration (``chorjax calibrate``;
    not with ``use_calibration`` False: what calibrating it again draws with), else its ``[sample]`` config,
    as the run's family applies them (a GAN records the frame-by-frame draw's controls as off, and reads no
    calibration)."""
    family = self.family
    calibrated = read_calibration(self.workdir) if use_calibration and self.workdir and family.calibrated else {}
    controls = Controls.resolve(self.config.sample, calibrated, **given)
    return controls if family.draws_frames else controls.without_frame_draw()

  def check_drawn(self, frames: int, what: str) -> None:
    """Refuses a draw of ``frames`` frames in all (frames x dancers) that this machine cannot hold: each
    frame's features and positions in float64, a few copies on the way out (``errors.check_draw``)."""
    check_draw(frames, self.features.dim + self.features.skeleton.num_joints * 3, what)

  def ranged(self, sampling: Controls) -> Run:
    """This run with the training range, per-frame changes and pace that ``sampling`` (``clamp``,
    ``clamp_steps``, ``pace``) holds to, the floor ``ground`` stands on, and the scale ceiling of ``scale_cap``
    (measured on the model's training frames). Runs trained before those were recorded get them from their
    training data; both read the training data, which must still give the very normalization the run was
    trained with."""
    f = self.features
    needs = (
      (sampling.clamp and f.low is None)
      or (sampling.pace and (f.pace is None or (f.pace_joints is None and f.joint_motion is not None)))
      or (sampling.pace and self.labels is not None and f.pace_by_label is None)
      or (sampling.ground and f.floor is None and f.representation == "canonical")
      or (sampling.clamp_steps and f.step_low is None)
    )
    if not needs and not sampling.scale_cap:
      return self
    if not needs:  # the ceiling alone: recorded with the run at the end of training, for its kept checkpoint
      ceiling = read_ceiling(self.workdir, self.step, sampling.scale_cap) if self.workdir else None
      if ceiling is not None and ceiling.shape in ((self.features.dim,), (1,)):
        return dataclasses.replace(self, features=dataclasses.replace(f, scale_ceiling=ceiling))

    what = "a training range or pace" if needs else "a scale ceiling"
    try:
      ds = load_dataset(self.config.data)
    except UserError as e:
      raise UserError(
        f"{self.workdir}: sampling needs {what} from its training data, which cannot be read ({e})"
      ) from None
    fresh = ds.features
    close = lambda a, b: np.allclose(a, b, atol=1e-5)
    same = fresh.dim == f.dim and close(fresh.mean, f.mean) and close(fresh.std, f.std)
    if not same:
      raise UserError(f"{self.workdir}: sampling needs {what} from its training data, which changed")
    keys = (*Features.RANGES, *Features.STEPS, "pace_lag", "pace", "pace_joints", "pace_by_label", "floor")
    stats = {k: getattr(fresh, k) for k in keys} if needs else {}
    f = dataclasses.replace(f, **stats)
    f = with_ceiling(f, self.graphdef, self.params, ds.train, self.config.data.seq_length, sampling)
    return dataclasses.replace(self, features=f)


CEILING = "scale_ceiling.json"  # sample.scale_cap's ceiling, measured on the training takes at the end of training


def save_ceiling(workdir, step: int, quantile: float, ceiling) -> Path:
  """Records ``sample.scale_cap``'s ceiling ``[S]`` of checkpoint ``step`` at ``quantile`` with the run."""
  doc = {"step": int(step), "quantile": float(quantile), "ceiling": [float(x) for x in np.asarray(ceiling)]}
  return atomic_write(Path(workdir) / CEILING, lambda p: p.write_text(json.dumps(doc) + "\n"))


def read_ceiling(workdir, step: int, quantile: float) -> np.ndarray | None:
  """The recorded ceiling of checkpoint ``step`` at ``quantile`` (None: not recorded for those, or unreadable:
  then it is measured on the training takes again)."""
  try:
    doc = load_json((Path(workdir) / CEILING).read_text())
    if doc["step"] != step or doc["quantile"] != quantile:
      return None
    ceiling = np.asarray(doc["ceiling"], np.float32)
  except (OSError, ValueError, KeyError, TypeError):
    return None
  return ceiling if ceiling.ndim == 1 and np.all(np.isfinite(ceiling) & (ceiling > 0)) else None


def _keeps_best(workdir: Path) -> bool:
  """Whether the run's config (``config.json``) says ``train.keep = "best"``."""
  try:
    return load_json((workdir / "config.json").read_text())["train"].get("keep") == "best"
  except (OSError, ValueError, KeyError, TypeError, AttributeError):
    return False


def load_run(workdir, which: str | int = "kept") -> Run:
  """The run in ``workdir`` at checkpoint ``which``: ``kept`` (what the run's ``train.keep`` names: the
  latest, or the best by validation loss), ``latest``, ``best`` or a step number.

  Raises:
    UserError: no such directory, no checkpoints, no such step, or a checkpoint that does not
      match its own config.
  """
  workdir = Path(workdir)
  if not workdir.is_dir():
    raise UserError(f"{workdir}: no such run directory")
  manager = ckpt.open_run(workdir)
  try:
    if which == "kept":
      which = "best" if _keeps_best(workdir) and ckpt.best_step(manager) is not None else "latest"
    step = ckpt.resolve_step(manager, which, workdir)
    try:
      meta, cfg, features, graphdef, params = _read_step(manager, step)
    except ckpt.Damaged as e:
      good = _intact_step(manager, [s for s in manager.all_steps() if s != step])
      hint = f"use --checkpoint {good} (intact)" if good is not None else "no other checkpoint is intact"
      raise UserError(f"{e}; {hint}") from None
  finally:
    manager.close()
  return Run(
    workdir=workdir,
    config=cfg,
    features=features,
    id_map=dict(meta["id_map"]),
    train_takes=tuple(meta.get("train_takes", ())),
    val_takes=tuple(meta.get("val_takes", ())),
    graphdef=graphdef,
    params=params,
    step=int(meta["step"]),
    val_loss=meta.get("val_loss"),
    joint_maps=dict(meta.get("joint_maps", {})),
    frame_rate=meta.get("fps"),
    labels=Labels.from_dict(meta["labels"]) if meta.get("labels") else None,
  )


def _read_step(manager, step: int):
  """``(meta, config, features, graphdef, params)`` of one checkpoint step (``ckpt.Damaged`` if unreadable)."""
  meta = ckpt.step_meta(manager, step)
  try:
    cfg = config_from_dict(meta["config"])
    features = Features.from_dict(meta["features"])
    graphdef, template = model_template(cfg, features, len(meta["id_map"]))
    meta = {**meta, "step": int(meta["step"])}  # a step that is no whole number is damage too
  except (KeyError, TypeError, ValueError) as e:  # (a UserError, e.g. a newer version's key, stays as it is)
    raise ckpt.Damaged(f"{manager.directory}/{step}/meta/metadata: damaged checkpoint ({e})", step) from None
  return meta, cfg, features, graphdef, ckpt.restore_params(manager, step, template)


def _intact_step(manager, steps) -> int | None:
  """The newest of ``steps`` that reads back whole (for the hint after a damaged one), or None."""
  for step in sorted(steps, reverse=True):
    with contextlib.suppress(ckpt.Damaged):
      _read_step(manager, step)
      return step
  return None


HELD_OUT = "held-out"  # --data held-out: the takes of the run's dataset it did not train on


def read_reference(run: Run, data: Sequence[str] | None) -> tuple[list, list]:
  """``(the takes in data, the run's training takes)``, read exactly as training read its takes; ``data`` of
  ``["held-out"]``: the takes of the run's own dataset that it did not train on; None: the training takes."""
  data_cfg = run.config.data
  trained = set(run.train_takes)
  heads, tails = with_tails(conform(read_takes([data_cfg.dataset], data_cfg), data_cfg), list(trained), data_cfg)
  every = [*heads, *tails]  # with data.val_tail: the training takes' tails are held out as takes of their own
  train = [m for m in every if m.name in trained] or every
  if data is None:
    return train, train
  if list(data) == [HELD_OUT]:
    real = [m for m in every if m.name not in trained]
    if not real:
      raise UserError(f"--data held-out: the run trained on every take of {data_cfg.dataset}; name takes to judge on")
  else:
    real = conform(read_takes(list(data), data_cfg), data_cfg)
  if not real:
    raise UserError(f"--data {' '.join(data)}: no takes")
  return real, train
