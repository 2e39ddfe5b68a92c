"""The recurrent family (``model.family = "rnn"``): chor-rnn's deep recurrent core over joint features,
predicting every next frame through a mixture-density (or MSE) head, sampled frame by frame.

* ``recurrent_model.py``: the model (core + head, conditioned on motion ids).
* ``steps.py``: its state, loss and jitted train / evaluation steps.
* ``generation.py``: the frame-by-frame draw, its controls, and live mode's endless stream.
"""

from __future__ import annotations

import jax
import numpy as np
from flax import nnx

from chorjax.data.dataset import WindowSampler, eval_windows
from chorjax.data.features import principal_axes
from chorjax.errors import UserError
from chorjax.families.family import Family
from chorjax.families.recurrent.generation import continue_stream, dance, frame_program, start_stream
from chorjax.families.recurrent.recurrent_model import create_model
from chorjax.families.recurrent.steps import (
  _train_step,
  create_train_state,
  eval_step,
  parted_train_step,
  sharded_train_step,
  train_step,
)
from chorjax.models.heads import frame_numbers, white_axes
from chorjax.registry import register


def mdn_basis(model_cfg, takes, white: int = 0):
  """The MDN's ``[D, D]`` coordinates (``model.mdn_basis``): the principal axes of the training frames
  (``takes``, ``[T, D]`` each) or of their second differences; the last ``white`` features
  (``heads.white_axes``) are axes of their own, left out of the others."""
  lag = 2 if model_cfg.mdn_basis == "acceleration" else 0
  d = takes[0].shape[-1]
  axes = principal_axes([np.diff(z[:, : d - white], lag, axis=0) for z in takes])
  basis = np.eye(d, dtype=np.float32)
  basis[: d - white, : d - white] = axes
  return basis


class Recurrent(Family):
  name = "rnn"
  data_parallel = True
  calibrated = True
  own_keys = frozenset({"model.lstm_kernel", "model.condition_every_frame", "train.batch_parts"})

  def check(self, cfg) -> None:
    if cfg.model.memory and cfg.train.feedback != "none" and cfg.train.feedback_draw == "mean":
      raise UserError(
        "model.mdn_memory feeds back what it draws (the residuals it carries are the draw's): "
        "set train.feedback_draw = 'sample' or model.mdn_memory = 0"
      )

  def build_model(self, cfg, features, num_motions: int):
    return create_model(cfg.model, features.dim, num_motions, cfg.train.seed, white_axes(cfg.model, features))

  def create_state(self, cfg, ds):
    white = white_axes(cfg.model, ds.features)
    basis = mdn_basis(cfg.model, [z for _, z in ds.train], white) if cfg.model.pca_basis else None
    return create_train_state(cfg, ds.features.dim, ds.num_motions, basis, white)

  def parts(self, cfg, ds):
    sampler = WindowSampler(ds.train, cfg.data.seq_length, cfg.train.batch_size, cfg.train.seed)
    val = eval_windows(ds.val, cfg.data.seq_length, cfg.train.val_windows)
    step = train_step if cfg.train.batch_parts == 1 else parted_train_step
    return step, sampler, val, lambda params, val, spec: eval_step(params, val, spec.graphdef)

  def window_loss(self, graphdef, params, windows: dict) -> float:
    return float(eval_step(params, windows, graphdef))

  def parallel_step(self, parallel):
    return sharded_train_step(parallel)

  dance = staticmethod(dance)  # pyright: ignore[reportAssignmentType]  (generation's, the family's arguments)

  def stream(self):
    return start_stream, continue_stream

  def frame_program(self, graphdef, params, features, draw, batch: int, num_motions: int):
    return frame_program(graphdef, params, draw, batch)

  def frame_numbers(self, graphdef, params, key, frames: int, batch: int):
    model = nnx.merge(graphdef, params)
    k, d = model.num_mixtures, model.dim
    return jax.vmap(lambda f: frame_numbers(f, batch, k, d))(jax.random.split(key, frames))

  def vector_step(self):
    return _train_step, eval_step


register(Recurrent())
