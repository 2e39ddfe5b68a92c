"""What a model family is to the rest of chorjax: the :class:`Family` base class, whose defaults describe a
family that generates dance frame by frame from motion ids, as the recurrent one does.

A family (``model.family``) brings its model, its train step, how it draws and the commands it serves; it
registers itself with ``registry.register``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import jax
import numpy as np

from chorjax.data.motion import Motion
from chorjax.errors import UserError
from chorjax.sampling.controls import with_ceiling

if TYPE_CHECKING:  # (the annotations only)
  from chorjax.sampling.controls import Controls


class Family:
  """A model family. Subclasses set ``name`` and override what they do; the defaults describe a family that
  generates dance frame by frame from motion ids, like the recurrent one.

  Attributes:
    name: the ``model.family`` value.
    likelihood: it has a held-out loss to report (``chorjax eval``, ``compare``'s axis).
    figures: training draws TensorBoard figures of its dance (``train.figure_every``).
    data_parallel: it trains data-parallel over processes (``[parallel]``).
    calibrated: its draw has the controls ``chorjax calibrate`` chooses (the run's calibration.json applies).
    conditioned: a dance is conditioned on a take or labels (``--motion``, ``--mix``); else drawn from noise alone.
    draws_frames: it draws frame by frame (the draw's controls apply); else they are recorded at their neutral
      values, the clip to the training range and decoding as given (``Controls.without_frame_draw``).
    section: the family's own config section (``[gan]``), a frozen dataclass of ``fields.config_field``s keyed
      by its name; None for none. The schema asks the registry for them (``registry.sections``).
    own_keys: the keys other families refuse, which this one reads (``model.lstm_kernel = "cudnn"``, ...).
  """

  name: str = ""
  likelihood: bool = True
  figures: bool = True
  data_parallel: bool = False
  calibrated: bool = False
  conditioned: bool = True
  draws_frames: bool = True
  section: tuple[str, type] | None = None
  own_keys: frozenset[str] = frozenset()

  def refusal(self, command: str) -> str | None:
    """Why this family's runs cannot serve ``command`` (``sample``, ``eval``, ``calibrate``, ``live``,
    ``inbetween``, ``export``), or None where they can (``Run.serving``)."""
    return (
      "not an in-betweening run (train one with model.family = 'inbetween': configs/inbetween.toml)"
      if command == "inbetween"
      else None
    )

  def columns(self, config: dict) -> tuple[str, str]:
    """``(cell, head)``: what a comparison report's table says of a run's model (``config``: its saved dict)."""
    return config["model"]["cell"], config["model"]["head"]

  def check(self, cfg) -> None:
    """Raises UserError, naming the key, for a config this family cannot train (before anything is written)."""

  def check_keys(self, cfg) -> None:
    """Raises UserError, naming the key, where ``cfg`` sets a key another family owns (``own_keys``) away from
    its default (``load_config`` asks)."""
    m, family = cfg.model, cfg.model.family
    if m.lstm_kernel == "cudnn" and ("model.lstm_kernel" not in self.own_keys or m.cell != "lstm"):
      raise UserError(
        f"key 'model.lstm_kernel': 'cudnn' runs the rnn family's plain LSTM only (model.family = 'rnn', "
        f"model.cell = 'lstm'); here model.family is {family!r} and model.cell {m.cell!r}"
      )
    if m.condition_every_frame and "model.condition_every_frame" not in self.own_keys:
      raise UserError(f"key 'model.condition_every_frame': the rnn family's only; model.family is {family!r}")
    if cfg.train.batch_parts > 1 and "train.batch_parts" not in self.own_keys:
      raise UserError(
        f"key 'train.batch_parts': only the rnn family computes its batch in shares (model.family = {family!r})"
      )

  def build_model(self, cfg, features, num_motions: int):
    """The family's model for ``features`` (an ``nnx.Module``), parameters drawn from ``train.seed``."""
    raise NotImplementedError

  def create_state(self, cfg, ds) -> tuple[dict, Any]:
    """``({params, opt_state, step}, spec)`` of a fresh run on the dataset ``ds``; ``spec`` is static."""
    raise NotImplementedError

  def parts(self, cfg, ds) -> tuple[Callable, Any, dict, Callable]:
    """``(jitted step(state, batch, key, spec), batch sampler, validation batch, val_loss(params, val, spec))``."""
    raise NotImplementedError

  def window_loss(self, graphdef, params, windows: dict) -> float:
    """The model's teacher-forced loss on ``windows`` (``data.dataset.eval_windows``), no noise, no dropout
    (families with ``likelihood``: ``chorjax eval``'s held-out loss)."""
    raise NotImplementedError

  def parallel_step(self, parallel) -> Callable:
    """The jitted step of a data-parallel run (families with ``data_parallel``)."""
    raise NotImplementedError

  def dance(self, graphdef, params, features, motion, key, num_frames: int, controls: Controls, prime=None):
    """Dancers in data space ``[B, T, J, 3]`` (``motion``: ids ``[B]`` or weights ``[B, M]``)."""
    raise NotImplementedError

  def end_sample(self, graphdef, params, ds, cfg, controls: Controls) -> tuple:
    """What a run ends with: ``(positions of samples/sample.csv, the motions of the player, its title)``;
    here ``sample.num`` dancers of ``sample.frames`` conditioned on take ``sample.motion`` (seed
    ``sample.seed``), the first in the CSV, all beside that take in the player."""
    s = cfg.sample
    features = with_ceiling(ds.features, graphdef, params, ds.train, cfg.data.seq_length, controls)
    key = jax.random.key(s.seed)
    motion = np.array([ds.condition(s.motion)] * s.num)
    pos = self.dance(graphdef, params, features, motion, key, s.frames, controls)
    sk, real = ds.features.skeleton, ds.motions[s.motion]
    name = real.name
    motions = [real.replace(positions=real.positions[: s.frames], name=f"original: {name}")]
    motions += [
      Motion(p, real.fps, sk, real.up_axis, real.units, name=f"generated #{i} (motion {s.motion})")
      for i, p in enumerate(pos)
    ]
    return pos[0], motions, f"chorjax: {cfg.name}"

  def transitions(self, run, context, targets, frames, key, num: int):
    """``num`` pieces ``[num, C + sum(frames) + len(targets), J, 3]``: the ``context`` phrase, then for each
    target pose its transition of ``frames[i]`` frames and the target (``chorjax inbetween``; a family whose
    runs serve that command)."""
    raise NotImplementedError

  def stream(self):
    """``(start_stream, continue_stream)``: live mode's endless draw (``chorjax.live.server``):
    ``start_stream(graphdef, params, motion [B, M], draw, prime [B, P, D] or None) -> state`` and
    ``continue_stream(graphdef, params, state, key, draw, *, num_frames) -> (state, frames [B, N, D])``,
    ``draw`` the run's ``Controls.draw`` (its temperatures may change between chunks)."""
    raise NotImplementedError

  def frame_program(
    self, graphdef, params, features, draw, batch: int, num_motions: int
  ) -> tuple[Callable, list, list[str], list[str]]:
    """One frame of the family's draw for ``batch`` dancers as a function of arrays (``chorjax export`` traces
    it into an ONNX graph): ``(program, example inputs, input names, output names)``; the inputs begin with
    ``weights [B, M]``, ``start [B]``, ``gumbel [B, K]``, ``normal [B, N]``, then the state; the outputs are
    ``frame [B, D]`` and the next state (families whose runs serve ``export``); ``M = num_motions``."""
    raise NotImplementedError

  def frame_numbers(self, graphdef, params, key, frames: int, batch: int) -> tuple:
    """``(gumbel [T, B, K], normal [T, B, N])``: the random numbers each frame of :meth:`dance` with ``key``
    is drawn with, as :meth:`frame_program` takes them (``chorjax.export.dancer.sample_numbers``)."""
    raise NotImplementedError

  def vector_step(self) -> tuple[Callable, Callable] | None:
    """``(step, loss)`` for training grid points as one vectorized program (``chorjax.training.vectorized``): the
    un-jitted ``step(state, batch, key, spec, lr_scale, noise) -> (state, metrics)`` with the learning-rate
    scale and the input noise traced, and ``loss(params, windows, graphdef)`` on ``data.dataset`` windows; or
    None where the family trains its points apart."""
    return None


def frame_io(template, top: tuple[str, ...], batch: int, num_motions: int, num_gumbel: int, num_normal: int):
  """What :meth:`Family.frame_program` returns beside its program, from the shapes of its state ``template``
  (a tuple of ``top`` parts): ``(treedef, example inputs, input names, output names)``: ``weights``,
  ``start`` (ones: every dancer starts), ``gumbel``, ``normal``, then each state leaf zeros, named by its
  place (``state.carry.0.1``); the outputs ``frame`` and each leaf's ``.next``."""
  paths, treedef = jax.tree_util.tree_flatten_with_path(template)

  def name(path) -> str:
    keys = [str(getattr(p, "idx", getattr(p, "key", p))) for p in path]
    return ".".join(["state", top[int(keys[0])], *keys[1:]])

  names = [name(path) for path, _ in paths]
  shapes = [(batch, num_motions), (batch,), (batch, num_gumbel), (batch, num_normal)]
  args = [np.zeros(s, np.float32) for s in shapes] + [np.zeros(leaf.shape, leaf.dtype) for _, leaf in paths]
  args[1][:] = 1.0
  return treedef, args, ["weights", "start", "gumbel", "normal", *names], ["frame", *[f"{n}.next" for n in names]]
