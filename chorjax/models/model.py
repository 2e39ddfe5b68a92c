"""The chor-rnn model: recurrent core + head, and its pure apply functions."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import nnx

from chorjax.models.heads import MDNHead, MSEHead
from chorjax.models.rnn import RecurrentCore


class ChorModel(nnx.Module):
  """Motion-conditioned recurrent model over normalized frames.

  ``model(x_BxTxD, weights_BxM)`` -> raw head outputs ``[B, T, P]`` for every next frame.
  ``model.step(carry, x_BxD)`` does the same for one frame, with the state carried (generation).
  """

  def __init__(self, cfg, dim: int, num_motions: int, *, rngs: nnx.Rngs):
    self.dim, self.num_motions = dim, num_motions
    self.core = RecurrentCore(cfg.cell, dim, cfg.hidden_size, cfg.num_layers, num_motions,
                              forget_bias=cfg.forget_bias, dropout=cfg.dropout,
                              initial_state=cfg.initial_state, rngs=rngs)
    if cfg.head == "mdn":
      self.head = MDNHead(cfg.hidden_size, dim, num_mixtures=cfg.num_mixtures,
                          isotropic=cfg.mdn_scale == "isotropic", min_scale=cfg.min_scale, rngs=rngs)
    else:
      self.head = MSEHead(cfg.hidden_size, dim, rngs=rngs)

  def __call__(self, x_BxTxD, weights_BxM, dropout_key=None):
    h, _ = self.core(x_BxTxD, self.core.initial_carry(weights_BxM), dropout_key)
    return self.head(h)

  def run(self, x_BxTxD, carry, dropout_key=None):
    """Teacher-forced pass from a given carry: ``(raw_BxTxP, final carry)`` (used for priming)."""
    h, carry = self.core(x_BxTxD, carry, dropout_key)
    return self.head(h), carry

  def initial_carry(self, weights_BxM):
    return self.core.initial_carry(weights_BxM)

  def step(self, carry, x_BxD):
    carry, h = self.core.step(carry, x_BxD)
    return carry, self.head(h)

  def loss(self, raw, targets):
    return self.head.loss(raw, targets)

  def sample(self, raw_BxP, key, pi_temperature=1.0, sigma_temperature=1.0, greedy=False):
    return self.head.sample(raw_BxP, key, pi_temperature, sigma_temperature, greedy)


def create_model(model_cfg, dim: int, num_motions: int, seed: int) -> ChorModel:
  return ChorModel(model_cfg, dim, num_motions, rngs=nnx.Rngs(params=seed))


def motion_weights(ids_B, num_motions: int):
  """One-hot motion-id weights ``[B, M]``."""
  return jax.nn.one_hot(ids_B, num_motions, dtype=jnp.float32)
