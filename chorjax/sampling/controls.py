"""Sampling controls, one typed value from the flags to the draw.

:class:`Controls` holds the controls of ``[sample]`` (declared in :mod:`chorjax.sampling.table`), resolved in one
place (:meth:`Controls.resolve`: a flag or keyword given, else the run's calibration, else its ``[sample]``).
It splits into what the draw uses (:class:`Draw`, with the training range as :class:`Bounds`, the pace
target as :class:`Pacing` and the scale ceiling filled in from the run's features) and what decoding uses
(:meth:`Controls.decoding`). ``Draw`` is a pytree: jitted generators take it whole, compiled once per
value of its static fields (``greedy``, the noise filters, the governor's gain and lag).
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import nnx

from chorjax.data.dataset import eval_windows
from chorjax.errors import UserError
from chorjax.models.heads import MDNHead
from chorjax.sampling.table import HEAD, NAMES, PLAIN, SWITCHES, TRACED, ControlFields, Given, check_sample_control

LABEL_PACE_WIDTH = 0.05  # two label combinations that differ in one value are 2 apart: each its own pace


@dataclasses.dataclass(frozen=True)
class Controls(ControlFields):
  """How to draw and decode a dance: each field is the ``[sample]`` key of its name (``chorjax config keys
  sample`` says what each does; ``chorjax.sampling.table`` declares them). A pytree: the numbers the draw
  traces are its leaves, the rest static."""

  @classmethod
  def names(cls) -> tuple[str, ...]:
    return NAMES

  @classmethod
  def resolve(cls, sample_config, calibrated: dict | None = None, **given) -> Controls:
    """The controls a draw uses: each one ``given`` (not None; a value, or a :class:`Given` that names the flag
    it came from), else ``calibrated`` (a run's calibration.json settings), else ``sample_config``'s (a
    ``SampleConfig``). A name that is no control is a UserError that suggests the closest."""
    names = cls.names()
    for name in [*given, *(calibrated or {})]:
      if name not in names:
        close = difflib.get_close_matches(name, names, n=1)
        raise UserError(f"{name!r} is not a sampling control" + (f"; did you mean {close[0]!r}?" if close else ""))

    # checked once, here, as the same keys are in a config file: a value the CLI, the API's keywords or a
    # calibration.json (edited by hand) gives that no [sample] could hold is refused, named by where it came from
    check = lambda k, v: check_sample_control(k, *((v.value, v.where) if isinstance(v, Given) else (v, k)))
    saved = {k: check_sample_control(k, v, "calibration.json") for k, v in (calibrated or {}).items()}
    given = {**saved, **{k: check(k, v) for k, v in given.items() if v is not None}}
    values = {k: given.get(k, getattr(sample_config, k)) for k in names}
    return cls(**{**values, **{k: bool(values[k]) for k in SWITCHES}})

  def replace(self, **changes) -> Controls:
    return dataclasses.replace(self, **changes)

  def without_frame_draw(self) -> Controls:
    """These controls with the frame-by-frame draw's at their neutral values (``PLAIN``), the clip to the
    training range and decoding as they are: what a family that makes whole sequences applies (GAN, patch)."""
    return self.replace(**{k: v for k, v in PLAIN.items() if k != "clamp"})

  def to_dict(self) -> dict:
    """``{name: value}`` in ``[sample]``'s order (what a sample's settings and an evaluation record)."""
    return dataclasses.asdict(self)

  def decoding(self) -> dict:
    """``Features.decode``'s keyword arguments."""
    return {"rigid": self.rigid_bones, "lock_feet": self.foot_lock, "ground": self.ground}

  def draw(self, features) -> Draw:
    """What the generator takes: the draw's controls, the training range (``clamp``, ``clamp_steps``), pace
    target (``pace``) and scale ceiling (``scale_cap``) filled in from ``features``. A UserError if the run
    cannot do what is asked (checked before generating, not after)."""
    try:
      features.check_decode(**self.decoding())
      if self.clamp and any(getattr(features, k) is None for k in features.RANGES):
        raise ValueError("clamp: this run records no training range (trained before the option existed)")
      if self.clamp_steps and any(getattr(features, k) is None for k in features.STEPS):
        raise ValueError("clamp_steps: this run records no training steps (Run.ranged measures them on its takes)")
      if self.pace and features.pace is None:
        raise ValueError("pace: this run records no training pace (trained before the option existed)")
      if self.scale_cap and features.scale_ceiling is None:
        raise ValueError("scale_cap: the run's scale ceiling was not measured (Run.ranged, controls.with_ceiling)")
    except ValueError as e:
      raise UserError(str(e)) from None
    made = {"bounds", "pacing", "scale_cap"}  # from the run's features; the other controls as they are
    return Draw(
      **{f.name: getattr(self, f.name) for f in dataclasses.fields(Draw) if f.name in NAMES and f.name not in made},
      bounds=Bounds.of(features, self.clamp, self.clamp_steps),
      pace_lag=features.pace_lag if self.pace else Draw.pace_lag,
      pacing=Pacing.of(features) if self.pace else None,
      scale_cap=features.scale_ceiling if self.scale_cap else None,
    )


jax.tree_util.register_dataclass(Controls, data_fields=list(TRACED), meta_fields=[n for n in NAMES if n not in TRACED])


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Bounds:
  """Every drawn frame is clipped to ``low``/``high`` ``[D]`` before it is fed back and returned; with
  ``step_low``/``step_high`` ``[D]``, its change from the previous frame is clipped to those first."""

  low: Any
  high: Any
  step_low: Any = None
  step_high: Any = None

  @classmethod
  def of(cls, features, clamp: bool, clamp_steps: bool) -> Bounds | None:
    """The training range (``clamp``) and the training frames' changes (``clamp_steps``) of ``features``."""
    if not (clamp or clamp_steps):
      return None
    if clamp:
      low, high = (getattr(features, k) for k in features.RANGES)
    else:
      low, high = np.full(features.dim, -np.inf, np.float32), np.full(features.dim, np.inf, np.float32)
    if not clamp_steps:
      return cls(low, high)
    return cls(low, high, *(getattr(features, k) for k in features.STEPS))

  def clip(self, x_BxD, previous_BxD=None):
    """``x`` held to the bounds (the step bounds from ``previous`` first, where there is one)."""
    if self.step_low is not None and previous_BxD is not None:
      x_BxD = previous_BxD + jnp.clip(x_BxD - previous_BxD, self.step_low, self.step_high)
    return jnp.clip(x_BxD, self.low, self.high)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Pacing:
  """The pace the governor holds a dancer to: ``ref``, the training pace over the lag, in the measure of
  ``joints`` (the judge's: joints relative to the root, turning included; ``Features.pace_joints``) or,
  for runs whose training data cannot tell how their joints move, ``weights`` ``[D]`` that average the pose
  features' change (``Features.pace``). Runs conditioned on labels carry the pace of each label combination
  of their training takes (``by_label``: ``Features.pace_by_label``), and :meth:`for_motion` turns ``ref``
  into each dancer's own: a run asked for a run dances at a run's pace, a wave at a wave's."""

  ref: Any
  joints: Any = None
  weights: Any = None
  by_label: Any = None

  @classmethod
  def of(cls, features) -> Pacing:
    by_label = features.pace_by_label
    if features.pace_joints is not None:  # canonical runs: the judge's measure
      return cls(features.pace_joints, joints=features.joint_motion, by_label=by_label)
    weights = np.zeros(features.dim, np.float32)
    weights[features.pose_channels] = 1.0 / len(features.pose_channels)
    return cls(features.pace, weights=weights, by_label=by_label)

  def for_motion(self, motion_BxM) -> Pacing:
    """The pace for dancers conditioned on label weights ``[B, M]``: ``ref`` ``[B]``, each dancer's the
    training pace of its labels; a blend, or labels the takes never combine, get the paces of the nearest
    combinations the takes hold, mixed in log space (a blend of two by its weights: softmax over the squared
    distances in weights / ``LABEL_PACE_WIDTH``). Unchanged without ``by_label`` or for take ids."""
    if self.by_label is None or jnp.ndim(motion_BxM) != 2:
      return self
    table = jnp.asarray(self.by_label)
    combos, log_pace = table[:, :-1], table[:, -1]
    w = jnp.asarray(motion_BxM, jnp.float32)
    apart = jnp.square(w[:, None, :] - combos[None]).sum(-1)  # [B, K]
    near = jax.nn.softmax(-apart / LABEL_PACE_WIDTH, axis=-1)
    return dataclasses.replace(self, ref=jnp.exp(near @ log_pace), by_label=None)


@functools.cache
def noise_gain(rho: float, order: int) -> float:
  """The factor that gives ``order`` cascaded AR(1) filters with coefficient ``rho`` unit stationary variance:
  one over the root energy of their impulse response ``C(k + order - 1, k) rho^k`` (for two filters
  ``(1 + rho^2) / (1 - rho^2)^3``)."""
  if order < 1 or not 0.0 <= rho < 1.0:
    raise ValueError(f"noise filters: need order >= 1 and 0 <= rho < 1, got {order}, {rho}")
  if order == 2:  # the closed form: the draws of runs before other orders existed, to the bit
    return ((1 - rho**2) ** 3 / (1 + rho**2)) ** 0.5
  k = np.arange(1, int(60 * order / (1 - rho)) + 100)  # the response has fallen below 1e-20 of its peak by then
  h = np.cumprod(np.r_[1.0, rho * (k + order - 1) / k])  # h_k = h_(k-1) rho (k + order - 1) / k
  return float(np.sum(h**2) ** -0.5)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Draw:
  """What the frame-by-frame draw takes (``Controls.draw``); defaults: full temperature, white noise, nothing
  held. ``greedy``, ``noise_order``, ``pace`` (the governor's gain) and ``pace_lag`` are static: a program is
  compiled for each value; the rest are traced (one program for every noise smoothing: calibration draws
  ten). ``noise_gain`` is :func:`noise_gain` of the smoothing and the order, filled in where they are made."""

  pi_temperature: Any = 1.0
  sigma_temperature: Any = 1.0
  greedy: bool = dataclasses.field(default=False, metadata={"static": True})
  noise_smoothing: Any = 0.0
  noise_order: int = dataclasses.field(default=2, metadata={"static": True})
  persistence: Any = 0.0
  crossfade: Any = 0.0
  bounds: Bounds | None = None
  pace: float = dataclasses.field(default=0.0, metadata={"static": True})
  pace_lag: int = dataclasses.field(default=15, metadata={"static": True})
  pacing: Pacing | None = None
  scale_cap: Any = None
  noise_gain: Any = None

  def __post_init__(self):
    if self.noise_gain is None:  # made here (not unflattened in a trace): the smoothing is a number
      object.__setattr__(self, "noise_gain", noise_gain(float(self.noise_smoothing), self.noise_order))

  def replace(self, **changes) -> Draw:
    if {"noise_smoothing", "noise_order"} & changes.keys():
      changes.setdefault("noise_gain", None)  # made again for the new filters
    return dataclasses.replace(self, **changes)

  def for_motion(self, motion) -> Draw:
    """This draw for dancers conditioned on ``motion`` (ids ``[B]`` or weights ``[B, M]``): with labels, the
    governor holds each to its labels' pace (:meth:`Pacing.for_motion`)."""
    if self.pacing is None or self.pacing.by_label is None:
      return self
    return self.replace(pacing=self.pacing.for_motion(motion))

  @property
  def plain(self) -> bool:
    """No smoothing, persistence, crossfade, governor or scale ceiling: the loop without the draw's state.
    (Decided before tracing, where persistence and crossfade are still numbers.)"""
    return bool(
      self.greedy
      or (self.noise_smoothing == self.persistence == self.crossfade == self.pace == 0 and self.scale_cap is None)
    )

  def head_args(self) -> dict:
    """The MDN draw's keyword arguments (``heads.MDNHead.draw``: the controls the table marks ``head``)."""
    return {name: getattr(self, name) for name in HEAD}


def scale_ceiling(graphdef, params, train, seq_length: int, quantile: float):
  """The ceiling ``sample.scale_cap`` holds MDN draws to: per feature, the ``quantile`` of the scales the
  model predicts for its own training frames (``train``: ``(motion id, features [T, D])`` per take;
  teacher forced, the most likely component's scale), ``[S]``; no ceiling (inf) for a head without scales
  (MSE)."""
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


def with_ceiling(features, graphdef, params, train, seq_length: int, controls: Controls):
  """``features`` with the scale ceiling that ``controls.scale_cap`` asks for (unchanged when off)."""
  q = controls.scale_cap
  if not q:
    return features
  return dataclasses.replace(features, scale_ceiling=scale_ceiling(graphdef, params, train, seq_length, q))
