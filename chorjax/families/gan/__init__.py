"""The LSTM-GAN family (``model.family = "gan"``): a generator turns a noise vector into a whole sequence, a
critic tells real from generated.

* ``networks.py``: the generator, the critic, the pose layers, and the draw of whole sequences.
* ``adversarial.py``: its state, the critic and generator steps, and the jitted train step.
"""

from __future__ import annotations

import numpy as np
from flax import nnx

from chorjax.data.dataset import WindowSampler
from chorjax.errors import UserError
from chorjax.families.family import Family
from chorjax.families.gan.adversarial import check_gan, create_gan_state, gan_train_step
from chorjax.families.gan.gan_config import GanConfig
from chorjax.families.gan.networks import (
  GanModel,
  frame_numbers,
  frame_program,
  generate_sequences,
  pose_layer,
)
from chorjax.registry import register


class Gan(Family):
  name = "gan"
  draws_frames = False  # whole sequences from noise
  likelihood = False
  conditioned = False
  section = ("gan", GanConfig)

  def refusal(self, command: str) -> str | None:
    if command == "calibrate":
      return "a GAN draws whole sequences from noise; there is nothing to calibrate"
    if command == "live":
      return "a GAN run writes whole sequences from noise; live mode streams the rnn family"
    return super().refusal(command)

  def columns(self, config: dict) -> tuple[str, str]:
    """The generator's cell; the adversarial loss in the head column."""
    return config["gan"]["cell"], f"gan ({config['gan']['loss']})"

  def check(self, cfg) -> None:
    check_gan(cfg, cfg.data.representation)

  def build_model(self, cfg, features, num_motions: int):
    return GanModel(cfg.gan, features.dim, rngs=nnx.Rngs(cfg.train.seed))

  def create_state(self, cfg, ds):
    return create_gan_state(cfg, ds.features)

  def parts(self, cfg, ds):

    # batches of critic_steps x batch_size windows; no likelihood to validate
    per_step = cfg.train.batch_size * cfg.gan.critic_steps
    sampler = WindowSampler(ds.train, cfg.data.seq_length, per_step, cfg.train.seed)
    return gan_train_step, sampler, {}, None

  def frame_program(self, graphdef, params, features, draw, batch: int, num_motions: int):
    return frame_program(graphdef, params, features, draw, batch, num_motions)

  def frame_numbers(self, graphdef, params, key, frames: int, batch: int):
    return frame_numbers(graphdef, params, key, frames, batch)

  def dance(self, graphdef, params, features, motion, key, num_frames, controls, prime=None):
    """Each dancer one sequence from noise (``motion`` only counts them; no prime)."""
    if prime is not None:
      raise UserError("--prime: a GAN draws whole sequences from noise; it cannot continue a phrase")
    controls = controls.without_frame_draw()
    model = nnx.merge(graphdef, params)
    assert isinstance(model, GanModel)
    projection = pose_layer(features, model.pose)
    b = controls.draw(features).bounds
    bounds = None if b is None else (b.low, b.high)
    num = int(np.shape(motion)[0])
    z = generate_sequences(graphdef, params, key, num=num, num_frames=num_frames, projection=projection, bounds=bounds)
    return np.asarray(features.decode(z, **controls.decoding()))


register(Gan())
