"""The in-betweening family (``model.family = "inbetween"``): transition models that write the frames between
a context phrase and a target pose (``chorjax inbetween``), no dance of their own.

* ``lstm_model.py``: the recurrent transition model (``inbetween.system = "lstm"``).
* ``cvae_model.py``: the two-stage CVAE (``inbetween.system = "cvae"``), and the model of either system.
* ``inbetweening.py``: the local space, transition batches, the train step, writing transitions, the benchmark.
* ``cvae_training.py``: the CVAE's two stages, losses and transitions.
"""

from __future__ import annotations

from chorjax.data.motion import Motion
from chorjax.families.family import Family
from chorjax.families.inbetween import inbetweening as ib
from chorjax.families.inbetween.cvae_model import transition_model
from chorjax.families.inbetween.inbetween_config import InbetweenConfig
from chorjax.families.inbetween.inbetweening import (
  check_inbetween,
  create_inbetween_state,
  end_sample,
  write_transitions,
)
from chorjax.registry import register

_NO_DANCE = (
  "an in-betweening run writes the frames between poses, not dance of its own; "
  "use `chorjax inbetween` (not `chorjax {command}`)"
)


class Inbetween(Family):
  name = "inbetween"
  figures = False
  section = ("inbetween", InbetweenConfig)

  def refusal(self, command: str) -> str | None:
    return None if command == "inbetween" else _NO_DANCE.format(command=command)

  def check(self, cfg) -> None:
    check_inbetween(cfg)

  def build_model(self, cfg, features, num_motions: int):
    return transition_model(cfg, features)

  def create_state(self, cfg, ds):
    return create_inbetween_state(cfg, ds.features)

  def parts(self, cfg, ds):
    space, icfg = ib.Space.of(ds.features), cfg.inbetween
    sampler = ib.TransitionSampler(ib.training_takes(ds, ds.augment), space, icfg, cfg.train.batch_size, cfg.train.seed)
    val = ib.validation_batch(ib.held_out_takes(ds), space, icfg, cfg.train.val_windows)
    return ib.inbetween_train_step, sampler, val, ib.validation_loss

  def end_sample(self, graphdef, params, ds, cfg, controls):
    """Key poses of a held-out take, the model writing every frame between, beside that take."""
    real, pieces, title = end_sample(graphdef, params, ds, cfg)
    motions = [real] + [Motion(p, real.fps, real.skeleton, real.up_axis, real.units, name=title) for p in pieces]
    return pieces[0], motions, cfg.name

  def transitions(self, run, context, targets, frames, key, num: int):
    return write_transitions(
      run.graphdef, run.params, run.features, run.config.inbetween, context, targets, frames, key, num
    )


register(Inbetween())
