"""The chor-rnn model: recurrent core + head, conditioned on motion ids."""

from __future__ import annotations

from flax import nnx

from chorjax.models.conditioning import as_weights
from chorjax.models.heads import MDNHead, MSEHead
from chorjax.models.rnn import RecurrentCore


class ChorModel(nnx.Module):
  """Motion-conditioned recurrent model over normalized frames.

  ``motion`` is what the model is conditioned on, as a language model takes tokens: integer ids
  ``[B]`` or weights ``[B, M]`` over the dataset's motions (a blend; see ``models.conditioning``).

  ``model(x_BxTxD, motion)`` -> head outputs ``[B, T, P]`` for every next frame.
  ``model.step(carry, x_BxD)`` does the same for one frame, with the state carried (generation).
  """

  def __init__(self, cfg, dim: int, num_motions: int, *, white: int = 0, rngs: nnx.Rngs):
    self.dim, self.num_motions = dim, num_motions
    self.core = RecurrentCore(
      cfg.cell,
      dim,
      cfg.hidden_size,
      cfg.num_layers,
      num_motions,
      forget_bias=cfg.forget_bias,
      dropout=cfg.dropout,
      initial_state=cfg.initial_state,
      lstm_kernel=cfg.lstm_kernel,
      every_frame=cfg.condition_every_frame,
      rngs=rngs,
    )
    self.head: MDNHead | MSEHead
    if cfg.head == "mdn":
      self.head = MDNHead(
        cfg.hidden_size,
        dim,
        num_mixtures=cfg.num_mixtures,
        isotropic=cfg.mdn_scale == "isotropic",
        min_scale=cfg.min_scale,
        basis=cfg.pca_basis,
        memory=cfg.memory,
        white=white,
        smooth=cfg.mdn_carry == "smooth",
        radius=cfg.mdn_radius,
        rngs=rngs,
      )
    else:
      self.head = MSEHead(cfg.hidden_size, dim, rngs=rngs)

  def __call__(self, x_BxTxD, motion, dropout_key=None):
    h_BxTxH, _ = self.core(x_BxTxD, self.initial_carry(motion), dropout_key)
    return self.head(h_BxTxH)

  def teacher_force(self, x_BxTxD, carry):
    """The whole phrase fed in from ``carry``: ``(head outputs [B, T, P], final carry)`` (priming)."""
    h_BxTxH, carry = self.core(x_BxTxD, carry)
    return self.head(h_BxTxH), carry

  def initial_carry(self, motion):
    """The recurrent state before the first frame, chosen by ``motion`` (ids or weights)."""
    return self.core.initial_carry(as_weights(motion, self.num_motions))

  def step(self, carry, x_BxD, masks=None):
    """One frame in: ``(carry, head outputs [B, P] for the next frame)``; ``masks``: the window's dropout
    masks (``core.dropout_masks``; training with feedback), None in generation."""
    carry, h_BxH = self.core.step(carry, x_BxD, masks)
    return carry, self.head(h_BxH)

  def loss(self, out, targets):
    return self.head.loss(out, targets)

  def sample(self, out_BxP, key, pi_temperature=1.0, sigma_temperature=1.0, greedy=False):
    return self.head.sample(out_BxP, key, pi_temperature, sigma_temperature, greedy)

  def draw(self, out_BxP, gumbel_BxK, noise_BxD, state, **controls):
    """A frame drawn with given random numbers and the sampler's state: ``(frame, state)`` (``heads``)."""
    return self.head.draw(out_BxP, gumbel_BxK, noise_BxD, state, **controls)

  def draw_start(self, x_BxTxD, out_BxTxP=None):
    """The head's draw state before the frame after the frames ``x`` (``out``: the outputs that predicted
    ``x[:, 1:]``, a prime's; None: nothing before ``x``)."""
    return self.head.draw_start(x_BxTxD, out_BxTxP)

  @property
  def remembers(self) -> bool:
    """Whether a frame's draw depends on the residuals of the frames before (``model.mdn_memory`` > 0)."""
    return bool(getattr(self.head, "correlated", False))

  @property
  def num_mixtures(self) -> int:
    """The components a frame is drawn from (1 for the MSE head: nothing to pick)."""
    return getattr(self.head, "num_mixtures", 1)

  def mean(self, out_xP):
    """The expected next frame (the MDN's mixture mean; the MSE head's output)."""
    return self.head.mean(out_xP)

  @property
  def num_outputs(self) -> int:
    return self.head.out.out_features


def create_model(model_cfg, dim: int, num_motions: int, seed: int, white: int = 0) -> ChorModel:
  """The model of ``model_cfg`` on ``dim`` features; ``white``: the MDN's last coordinates that carry no
  residuals (``heads.white_axes``)."""
  return ChorModel(model_cfg, dim, num_motions, white=white, rngs=nnx.Rngs(params=seed))
