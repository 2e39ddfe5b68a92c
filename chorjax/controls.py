"""Sampling controls as the draw and the decoder take them: what ``[sample]``, a run's calibration and the
flags resolve to (``SampleConfig.controls``), split into the generator's arguments (the training range,
step limits, pace target and scale ceiling filled in from the run's features) and the decoder's."""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np
from flax import nnx

from chorjax.errors import UserError


def decoding(controls: dict) -> dict:
  """``Features.decode``'s keyword arguments for ``controls`` (``SampleConfig.controls``)."""
  return {"rigid": controls["rigid_bones"], "lock_feet": controls["foot_lock"], "ground": controls.get("ground", False)}


def draw_controls(features, controls: dict) -> dict:
  """:func:`generate`'s keyword arguments for ``controls`` (``SampleConfig.controls``): the decode-time
  ones left out, the training range (``clamp``) and pace target (``pace``) filled in from ``features``.
  Raises UserError if the run cannot do what is asked (checked before generating, not after)."""
  try:
    features.check_decode(
      controls["rigid_bones"],
      controls["foot_lock"],
      controls["clamp"],
      controls["pace"],
      controls.get("ground", False),
      controls.get("clamp_steps", False),
    )
    if controls.get("scale_cap") and features.scale_ceiling is None:
      raise ValueError("scale_cap: the run's scale ceiling was not measured (Run.ranged, run.with_ceiling)")
  except ValueError as e:
    raise UserError(str(e)) from None
  decoded = ("rigid_bones", "foot_lock", "ground", "clamp", "clamp_steps", "scale_cap")
  drawn = {k: v for k, v in controls.items() if k not in decoded}
  if controls.get("scale_cap"):
    drawn["scale_cap"] = features.scale_ceiling
  if controls["clamp"]:
    drawn["bounds"] = tuple(getattr(features, k) for k in features.RANGES)
  if controls.get("clamp_steps"):
    span = drawn.get("bounds") or (
      np.full(features.dim, -np.inf, np.float32),
      np.full(features.dim, np.inf, np.float32),
    )
    drawn["bounds"] = (*span, *(getattr(features, k) for k in features.STEPS))
  if controls["pace"] and features.pace_joints is not None:  # canonical runs: the judge's measure
    drawn.update(pace_lag=features.pace_lag, pace_target=(features.pace_joints, features.joint_motion))
  elif controls["pace"]:  # runs whose training data cannot tell how their joints move
    weights = np.zeros(features.dim, np.float32)
    weights[features.pose_channels] = 1.0 / len(features.pose_channels)
    drawn.update(pace_lag=features.pace_lag, pace_target=(features.pace, weights))
  return drawn


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
