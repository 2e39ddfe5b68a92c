"""Stacked, scanned recurrent core with a motion-id initial state.

The motion-id conditioning follows the reference notebook: a weight vector over the dataset's
motions (one-hot, or a blend such as 0.5/0.5) goes through one dense layer that produces the initial
carry of every layer, so the id chooses the choreography. ``initial_state='zero'`` turns it off.
``every_frame`` also puts the weights beside every frame's input (``model.condition_every_frame``): an initial
state fades within seconds, and a library's labels have to hold for a whole dance.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import nnx

from chorjax.models.cells import CELLS


def on_cuda() -> bool:
  """Whether JAX computes on an NVIDIA GPU (where ``model.lstm_kernel = "cudnn"`` takes effect)."""
  return jax.default_backend() == "gpu" and "NVIDIA" in jax.devices()[0].device_kind


def dropout_mask(key, shape_BxH, rate: float):
  """One inverted-dropout mask per sequence, reused at every time step (variational dropout)."""
  keep = jax.random.bernoulli(key, 1.0 - rate, shape_BxH)
  return keep.astype(jnp.float32) / (1.0 - rate)


class RecurrentCore(nnx.Module):
  """``num_layers`` cells of ``hidden`` units, each scanned over time."""

  def __init__(
    self,
    cell: str,
    in_features: int,
    hidden: int,
    num_layers: int,
    num_motions: int,
    *,
    forget_bias: float = 1.0,
    dropout: float = 0.0,
    initial_state: str = "motion",
    lstm_kernel: str = "fused",
    every_frame: bool = False,
    rngs: nnx.Rngs,
  ):
    cls = CELLS[cell]
    self.lstm_kernel = lstm_kernel
    self.hidden, self.num_layers, self.dropout = hidden, num_layers, dropout
    self.num_carries = cls.num_carries
    self.every_frame = every_frame
    first = in_features + (num_motions if every_frame else 0)
    self.cells = nnx.List(
      [cls(first if l == 0 else hidden, hidden, forget_bias=forget_bias, rngs=rngs) for l in range(num_layers)]
    )
    self.initial_state = initial_state
    if initial_state == "motion":
      self.init_proj = nnx.Linear(
        num_motions, num_layers * self.num_carries * hidden, rngs=rngs, kernel_init=nnx.initializers.normal(0.1)
      )

  def initial_carry(self, weights_BxM):
    """Per layer, a tuple of ``[B, H]`` arrays, from motion-id weights ``[B, M]``; with ``every_frame``, then
    ``(weights,)``: the weights ride in the carry, so every frame's input gets them."""
    b = weights_BxM.shape[0]
    if self.initial_state == "zero":
      z = jnp.zeros((b, self.hidden), weights_BxM.dtype)
      layers = tuple(tuple(z for _ in range(self.num_carries)) for _ in range(self.num_layers))
    else:
      flat = self.init_proj(weights_BxM).reshape(b, self.num_layers, self.num_carries, self.hidden)
      layers = tuple(tuple(flat[:, l, k] for k in range(self.num_carries)) for l in range(self.num_layers))
    return (*layers, (weights_BxM,)) if self.every_frame else layers

  def _conditioned(self, carry, x):
    """``x`` (``[..., B, D]``) with the carry's motion weights beside each frame, where ``every_frame``."""
    if not self.every_frame:
      return x
    w = carry[-1][0].astype(x.dtype)
    return jnp.concatenate([x, jnp.broadcast_to(w, (*x.shape[:-1], w.shape[-1]))], -1)

  def _with_weights(self, carry, new_layers: list) -> tuple:
    return (*new_layers, carry[-1]) if self.every_frame else tuple(new_layers)

  def __call__(self, x_BxTxD, carry, dropout_key=None):
    """Runs the stack over a window: ``([B, T, H] top-layer outputs, final carry)``.

    Dropout (when ``dropout_key`` is given and the rate is > 0) drops the same units of each
    layer's output at every time step. Inside, the window is time-major (one transpose in, one out).
    """
    new_carry = []
    inp = self._conditioned(carry, jnp.swapaxes(x_BxTxD, 0, 1))
    cudnn = self.lstm_kernel == "cudnn" and on_cuda()
    drop = dropout_key is not None and self.dropout > 0
    masks = self.dropout_masks(dropout_key, inp.shape[1]) if drop else None
    for l, cell in enumerate(self.cells):
      if cudnn:
        c, inp = cell.cudnn_scan(carry[l], inp)
      else:
        c, inp = cell.scan(carry[l], cell.project(inp))  # one big matmul, outside the time loop
      new_carry.append(c)
      if masks is not None:
        inp = inp * masks[l]
    return jnp.swapaxes(inp, 0, 1), self._with_weights(carry, new_carry)

  def dropout_masks(self, key, batch: int) -> tuple:
    """Each layer's variational dropout mask ``[B, H]`` for a window drawn with ``key`` (what the whole-window
    call uses; ``step`` takes them to run the same window frame by frame)."""
    shape = (batch, self.hidden)
    return tuple(dropout_mask(jax.random.fold_in(key, l), shape, self.dropout) for l in range(self.num_layers))

  def step(self, carry, x_BxD, masks=None):
    """One frame through every layer: ``(carry, h_BxH)``. No dropout unless ``masks`` (``dropout_masks``)
    are given: generation has none; training with feedback runs a window frame by frame with them."""
    new_carry = []
    x_BxD = self._conditioned(carry, x_BxD)
    for l, cell in enumerate(self.cells):
      c, x_BxD = cell.step(carry[l], cell.project(x_BxD))
      new_carry.append(c)
      if masks is not None:
        x_BxD = x_BxD * masks[l]
    return self._with_weights(carry, new_carry), x_BxD
