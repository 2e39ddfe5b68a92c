"""A run's state: the optimizer, a fresh train state, the meta saved with it, and a run loaded back.

Training and sampling both stand on this module and it imports neither: data -> models -> run ->
train, sample -> cli.

* :func:`create_train_state` builds ``{params, opt_state, step}`` and the static :class:`StepSpec`
  the jitted train step needs (graph, optimizer, schedule, noise, dropout).
* :func:`run_meta` is the JSON that every checkpoint carries (config, features, motion ids, takes).
* :func:`load_run` reads a run directory back as a typed :class:`Run` with its params restored on
  their own (no optimizer is built), for sampling and evaluation.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import nnx

from chorjax import checkpoint as ckpt
from chorjax.config import Config, config_from_dict
from chorjax.data.features import Features
from chorjax.errors import UserError, check_memory
from chorjax.models import ChorModel, create_model
from chorjax.models.cvae import TransitionCVAE
from chorjax.models.gan import GanModel, gan_controls
from chorjax.models.inbetween import TransitionModel


@dataclasses.dataclass(frozen=True)
class Feedback:
  """How training feeds the model's own outputs back as inputs (see ``train.feedback``)."""

  mode: str  # "auto" or "scheduled"
  ground_truth_frames: int
  condition_frames: int
  max_fraction: float
  warmup: int
  ramp: int
  draw: str  # "sample" or "mean"
  pi_temperature: float
  sigma_temperature: float

  @classmethod
  def of(cls, cfg: Config) -> Feedback | None:
    t = cfg.train
    if t.feedback == "none":
      return None
    return cls(
      t.feedback,
      t.ground_truth_frames,
      t.condition_frames,
      t.feedback_max,
      t.feedback_warmup,
      t.feedback_ramp,
      t.feedback_draw,
      cfg.sample.pi_temperature,
      cfg.sample.sigma_temperature,
    )


@dataclasses.dataclass(frozen=True)
class StepSpec:
  """What the train step needs besides its arrays; hashable, so it is a static jit argument.

  Attributes:
    graphdef: the model's static graph (``nnx.split``).
    tx: the optax optimizer chain.
    schedule: learning rate as a function of the step (logged).
    input_noise: std of Gaussian noise added to the inputs (normalized units).
    dropout: the model's dropout rate (0 = no dropout key is drawn).
    feedback: own outputs fed back as inputs (None = teacher forcing only).
  """

  graphdef: Any
  tx: optax.GradientTransformation
  schedule: optax.Schedule
  input_noise: float
  dropout: float
  feedback: Feedback | None = None


def create_optimizer(
  cfg: Config, lr: float | None = None, schedule: optax.Schedule | None = None
) -> tuple[optax.GradientTransformation, optax.Schedule]:
  """The optax chain of ``cfg.optim``: optional global-norm clipping, then the optimizer; ``lr``: the peak
  learning rate instead of ``optim.lr`` (the GAN family's two networks); ``schedule``: a learning-rate
  schedule instead of ``optim.schedule``'s (the cvae system's stage 1)."""
  o = cfg.optim
  peak = o.lr if lr is None else lr
  if schedule is None and o.schedule == "warmup_cosine":
    schedule = optax.warmup_cosine_decay_schedule(
      0.0, peak, o.warmup_steps, max(cfg.train.num_steps, o.warmup_steps + 1), end_value=peak * o.final_lr_ratio
    )
  elif schedule is None:
    schedule = optax.constant_schedule(peak)
  if o.name == "adam":
    opt = optax.adam(schedule, b1=o.b1, b2=o.b2)
  elif o.name == "adamw":
    opt = optax.adamw(schedule, b1=o.b1, b2=o.b2, weight_decay=o.weight_decay, mask=_decayed)
  else:
    opt = optax.amsgrad(schedule, b1=o.b1, b2=o.b2)
  chain = [optax.clip_by_global_norm(o.clip_norm)] if o.clip_norm > 0 else []
  return optax.chain(*chain, opt), schedule


def _decayed(params):
  """Weight decay's mask: every parameter but a fixed basis (``model.mdn_basis``), which is never trained."""
  is_basis = lambda path: any(getattr(k, "key", None) == "basis" for k in path)
  return jax.tree_util.tree_map_with_path(lambda path, _: not is_basis(path), params)


def build_model(
  cfg: Config, features: Features, num_motions: int
) -> ChorModel | GanModel | TransitionModel | TransitionCVAE:
  """``cfg``'s model, of its family (``model.family``), for ``features``; parameters drawn from ``train.seed``.
  The in-betweening family works on flat joint positions (``3J`` numbers), the others on the features."""
  if cfg.model.family == "gan":
    return GanModel(cfg.gan, features.dim, rngs=nnx.Rngs(cfg.train.seed))
  if cfg.model.family == "inbetween":
    dim, rngs = 3 * features.skeleton.num_joints, nnx.Rngs(cfg.train.seed)
    if cfg.inbetween.system == "cvae":
      return TransitionCVAE(cfg.model, cfg.inbetween, dim, features.skeleton.root, rngs=rngs)
    return TransitionModel(cfg.model, cfg.inbetween, dim, rngs=rngs)
  return create_model(cfg.model, features.dim, num_motions, cfg.train.seed)


def update_part(state, part: str, tx, loss_fn, *args):
  """One optimizer step on ``state["params"][part]`` alone (a GAN's critic, a CVAE's sampler, ...):
  ``loss_fn(part_params, *args) -> (loss, aux)`` is differentiated and ``tx`` updates that part and its
  optimizer state; the other parts pass through. ``(state, loss, aux, grads)``; the step count is the caller's."""
  params, opt = state["params"], state["opt_state"]
  (loss, aux), grads = jax.value_and_grad(loss_fn, has_aux=True)(params[part], *args)
  updates, part_opt = tx.update(grads, opt[part], params[part])
  new = optax.apply_updates(params[part], updates)
  return {**state, "params": {**params, part: new}, "opt_state": {**opt, part: part_opt}}, loss, aux, grads


def step_key(key, step):
  """The train step's PRNG key: ``key`` (a typed key, or raw uint32 key data replicated across processes)
  folded with ``step``, so a resumed run draws what the uninterrupted one drew."""
  if not jnp.issubdtype(key.dtype, jax.dtypes.prng_key):
    key = jax.random.wrap_key_data(key)
  return jax.random.fold_in(key, step)


def create_train_state(cfg: Config, dim: int, num_motions: int, basis=None) -> tuple[dict, StepSpec]:
  """``({params, opt_state, step}, spec)`` for a fresh run of ``cfg`` (the rnn family) on ``dim`` features;
  ``basis``: the MDN's ``[D, D]`` coordinates where ``model.mdn_basis = "pca"`` (``features.principal_axes``
  of the training frames)."""
  model = create_model(cfg.model, dim, num_motions, cfg.train.seed)
  graphdef, params = nnx.split(model, nnx.Param)
  params = nnx.to_pure_dict(params)
  if cfg.model.pca_basis:
    if basis is None or np.shape(basis) != (dim, dim):
      raise ValueError(
        f"model.mdn_basis = 'pca' needs a [{dim}, {dim}] basis, got {basis if basis is None else np.shape(basis)}"
      )
    params["head"]["basis"] = jnp.asarray(basis, jnp.float32)
  tx, schedule = create_optimizer(cfg)
  state = {"params": params, "opt_state": tx.init(params), "step": jnp.zeros((), jnp.int32)}
  return state, StepSpec(graphdef, tx, schedule, cfg.train.input_noise, cfg.model.dropout, Feedback.of(cfg))


def model_template(cfg: Config, features: Features, num_motions: int) -> tuple[Any, dict]:
  """``(graphdef, abstract params)`` of ``cfg``'s model (any family), without computing any parameter."""
  model = nnx.eval_shape(lambda: build_model(cfg, features, num_motions))
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
  }


@dataclasses.dataclass(frozen=True)
class Run:
  """A trained run loaded from its directory.

  Attributes:
    workdir: the run directory.
    config: the run's resolved config.
    features: the fitted feature pipeline (data space <-> model features).
    id_map: take name -> motion id.
    train_takes, val_takes: the split it was trained on.
    graphdef, params: the model (``nnx.merge(graphdef, params)``).
    step: the checkpoint's step.
    val_loss: the validation loss saved with that checkpoint (None without held-out takes).
    joint_maps: take name -> how it was mapped onto the 16-joint layout (``Mapping.to_dict()``).
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

  @property
  def num_motions(self) -> int:
    return len(self.id_map)

  @property
  def fps(self) -> float:
    """The frame rate of the training takes (runs from before it was recorded: ``data.fps``)."""
    return self.frame_rate or self.config.data.fps

  @property
  def is_gan(self) -> bool:
    return self.config.model.family == "gan"

  @property
  def is_inbetween(self) -> bool:
    return self.config.model.family == "inbetween"

  def generating(self, command: str) -> Run:
    """This run, for ``command``, which generates dance on its own: an in-betweening run cannot (UserError)."""
    if self.is_inbetween:
      raise UserError(
        f"{self.workdir}: an in-betweening run writes the frames between poses, not dance of its own; "
        f"use `chorjax inbetween` (not `chorjax {command}`)"
      )
    return self

  def sampling(self, **given) -> dict:
    """Sampling controls: the ones given (not None), else the run's calibration (``chorjax calibrate``),
    else its ``[sample]`` config. A GAN draws whole sequences from noise: the frame-by-frame MDN draw
    controls do not apply and are recorded as off."""
    calibrated = read_calibration(self.workdir) if self.workdir and not self.is_gan else {}
    controls = self.config.sample.controls(**{**calibrated, **{k: v for k, v in given.items() if v is not None}})
    return gan_controls(controls) if self.is_gan else controls

  def check_drawn(self, frames: int, what: str) -> None:
    """Refuses a draw of ``frames`` frames in all (frames x dancers) that this machine cannot hold: each
    frame's features and positions in float64, a few copies on the way out (``errors.check_memory``)."""
    f = self.features
    check_memory(frames * (f.dim + f.skeleton.num_joints * 3) * 8 * 6, what)

  def ranged(self, sampling: dict) -> Run:
    """This run with the training range, per-frame changes and pace that ``sampling`` (``clamp``,
    ``clamp_steps``, ``pace``) holds to, the floor ``ground`` stands on, and the scale ceiling of ``scale_cap``
    (measured on the model's training frames). Runs trained before those were recorded get them from their
    training data; both read the training data, which must still give the very normalization the run was
    trained with."""
    f = self.features
    needs = (
      (sampling.get("clamp") and f.low is None)
      or (sampling.get("pace") and (f.pace is None or (f.pace_joints is None and f.joint_motion is not None)))
      or (sampling.get("ground") and f.floor is None and f.representation == "canonical")
      or (sampling.get("clamp_steps") and f.step_low is None)
    )
    if not needs and not sampling.get("scale_cap"):
      return self
    from chorjax.data.dataset import load_dataset

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
    keys = (*Features.RANGES, *Features.STEPS, "pace_lag", "pace", "pace_joints", "floor")
    stats = {k: getattr(fresh, k) for k in keys} if needs else {}
    f = dataclasses.replace(f, **stats)
    f = with_ceiling(f, self.graphdef, self.params, ds.train, self.config.data.seq_length, sampling)
    return dataclasses.replace(self, features=f)


# What calibration.json's settings may hold: what `chorjax calibrate` chooses, and the noise order and governor
# gain it was chosen with (runs calibrated before 2026-11-25 hold noise_smoothing and sigma_temperature alone;
# before 2026-11-27 no noise_order, and before session 27 of that day no pace: they were chosen with the run's
# sample.noise_order and sample.pace)
CALIBRATED = ("noise_smoothing", "noise_order", "pace", "sigma_temperature", "persistence", "crossfade", "foot_lock")


def calibration_path(workdir) -> Path:
  return Path(workdir) / "calibration.json"


def _damaged_calibration(workdir) -> UserError:
  return UserError(
    f"{calibration_path(workdir)}: damaged calibration; run `chorjax calibrate {workdir}` again (or delete it)"
  )


def _calibration(workdir) -> dict | None:
  """``calibration.json`` as a dict (None when the run was never calibrated); one line if it is not JSON."""
  path = calibration_path(workdir)
  if not path.is_file():
    return None
  try:
    return json.loads(path.read_text(errors="replace"))
  except json.JSONDecodeError:
    raise _damaged_calibration(workdir) from None


def read_calibration(workdir) -> dict:
  """The calibrated controls of a run (``{}`` when it was never calibrated)."""
  cal = _calibration(workdir)
  if cal is None:
    return {}
  try:
    settings = cal["settings"]
  except (KeyError, TypeError):
    raise _damaged_calibration(workdir) from None
  if not isinstance(settings, dict) or set(settings) - set(CALIBRATED):
    raise _damaged_calibration(workdir)
  return settings


def chosen_calibration_row(workdir) -> dict | None:
  """The row of ``calibration.json``'s table measured with the settings it chose (its objective and rates
  against the run's training takes); None if the run was never calibrated or its settings were edited by
  hand (no measured row is theirs)."""
  cal = _calibration(workdir)
  if cal is None:
    return None
  try:
    return next((r for r in cal["table"] if r["settings"] == cal["settings"]), None)
  except (KeyError, TypeError, AttributeError):
    raise _damaged_calibration(workdir) from None


def _keeps_best(workdir: Path) -> bool:
  """Whether the run's config (``config.json``) says ``train.keep = "best"``."""
  try:
    return json.loads((workdir / "config.json").read_text())["train"].get("keep") == "best"
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
  )


def _read_step(manager, step: int):
  """``(meta, config, features, graphdef, params)`` of one checkpoint step (``ckpt.Damaged`` if unreadable)."""
  meta = ckpt.step_meta(manager, step)
  try:
    cfg = config_from_dict(meta["config"])
    features = Features.from_dict(meta["features"])
    graphdef, template = model_template(cfg, features, len(meta["id_map"]))
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


def scale_ceiling(graphdef, params, train, seq_length: int, quantile: float):
  """The ceiling ``sample.scale_cap`` holds MDN draws to: per feature, the ``quantile`` of the scales the
  model predicts for its own training frames (``train``: ``(motion id, features [T, D])`` per take;
  teacher forced, the most likely component's scale), ``[S]``; no ceiling (inf) for a head without scales
  (MSE)."""
  from chorjax.data.dataset import eval_windows
  from chorjax.models.heads import MDNHead

  model = nnx.merge(graphdef, params)
  if not isinstance(getattr(model, "head", None), MDNHead):
    return np.full(1, np.inf, np.float32)
  win = eval_windows(train, seq_length, max_windows=256)
  if not win:
    raise UserError("scale_cap: the training takes are shorter than one window")
  logpi, _, scale = model.head.params(model(jnp.asarray(win["inputs"]), jnp.asarray(win["motion_ids"])))
  top = jnp.argmax(logpi, axis=-1)[..., None, None]
  scale_NxS = jnp.take_along_axis(scale, top, axis=-2)[..., 0, :].reshape(-1, scale.shape[-1])
  return np.quantile(np.asarray(scale_NxS), quantile, axis=0).astype(np.float32)


def with_ceiling(features, graphdef, params, train, seq_length: int, controls: dict):
  """``features`` with the scale ceiling that ``controls["scale_cap"]`` asks for (unchanged when off)."""
  q = controls.get("scale_cap")
  if not q:
    return features
  return dataclasses.replace(features, scale_ceiling=scale_ceiling(graphdef, params, train, seq_length, q))


HELD_OUT = "held-out"  # --data held-out: the takes of the run's dataset it did not train on


def read_reference(run: Run, data: Sequence[str] | None) -> tuple[list, list]:
  """``(the takes in data, the run's training takes)``, read exactly as training read its takes; ``data`` of
  ``["held-out"]``: the takes of the run's own dataset that it did not train on; None: the training takes."""
  from chorjax.data.dataset import conform, read_takes

  data_cfg = run.config.data
  every = conform(read_takes([data_cfg.dataset], data_cfg), data_cfg)
  trained = set(run.train_takes)
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
