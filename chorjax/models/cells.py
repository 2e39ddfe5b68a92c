"""Single-step recurrent cells: LSTM, layer-normalized LSTM (Ba et al. 2016) and GRU.

Every cell splits one frame's work in three so that training and sampling share one code path and
training can be fast:

* ``project(x_...xD) -> xp_...xG``: everything that depends on the input only. Training applies it
  to a whole window at once (one large matmul, hoisted out of the time loop).
* the recurrent matmul ``r = h @ w_h`` (the only work that must stay inside the loop);
* ``recurrent_update(loop_params, xp_BxG, r_BxG, carry) -> (carry, h_BxH)``: pure elementwise work
  (gates, layer norms), with ``loop_params`` the cell's biases and gains used inside the time loop.

``step(carry, xp)`` = ``recurrent_update(loop_params, xp, h @ w_h, carry)`` is what sampling calls
once per frame. ``scan(carry, xp_TxBxG)`` runs a whole (time-major) window through the fused layers of
:mod:`chorjax.models.fused` (the same numbers as ``lax.scan`` of ``step``, faster gradients; the tests
compare the two).
A carry is a tuple of ``[B, H]`` arrays whose LAST entry is h: ``(c, h)`` for the LSTMs, ``(h,)``
for the GRU.
"""

from __future__ import annotations

from typing import cast

import jax.numpy as jnp
from flax import nnx
from jax.experimental import rnn

from chorjax.models.fused import (
  dense,
  gru_scan,
  gru_step,
  layer_norm,
  lnlstm_scan,
  lnlstm_step,
  lstm_gates,
  lstm_scan,
  lstm_update,
)


def _kernel(rngs, shape, init):
  return nnx.Param(init(rngs.params(), shape, jnp.float32))


class _Cell(nnx.Module):
  w_h: nnx.Param

  def loop_params(self) -> dict:
    """The biases and gains ``recurrent_update`` needs inside the time loop."""
    return {}

  def step(self, carry, xp_BxG):
    return self.recurrent_update(self.loop_params(), xp_BxG, carry[-1] @ self.w_h[...], carry)

  @staticmethod
  def recurrent_update(loop_params, xp_BxG, r_BxG, carry):
    raise NotImplementedError


class LSTMCell(_Cell):
  """LSTM (gates i, f, g, o); forget-gate bias initialized to ``forget_bias``."""

  num_carries = 2

  def __init__(self, in_features: int, hidden: int, *, forget_bias: float = 1.0, rngs: nnx.Rngs):
    self.hidden = hidden
    self.w_x = _kernel(rngs, (in_features, 4 * hidden), nnx.initializers.glorot_uniform())
    self.w_h = _kernel(rngs, (hidden, 4 * hidden), nnx.initializers.orthogonal())
    self.b = nnx.Param(jnp.zeros((4 * hidden,)).at[hidden : 2 * hidden].set(forget_bias))

  def project(self, x):
    return dense(x, self.w_x[...]) + self.b[...]

  @staticmethod
  def recurrent_update(loop_params, xp_Bx4H, r_Bx4H, carry):
    c, h = lstm_update(lstm_gates(xp_Bx4H + r_Bx4H), carry[0])
    return (c, h), h

  def scan(self, carry, xp_TxBx4H):
    return lstm_scan(self.w_h[...], xp_TxBx4H, *carry)

  def cudnn_weights(self):
    """The cell's parameters in cuDNN's flat layout for one layer (``jax.experimental.rnn``): ``W_ih [4H, D]``,
    ``W_hh [4H, H]``, ``b_ih``, ``b_hh`` (zero: the cell has one bias); the gates in the same order."""
    b = self.b[...]
    return jnp.concatenate([self.w_x[...].T.ravel(), self.w_h[...].T.ravel(), b, jnp.zeros_like(b)])

  def cudnn_scan(self, carry, x_TxBxD):
    """``scan(carry, project(x))`` as one cuDNN call (CUDA only; the numerics are ``scan``'s, see the tests)."""
    c0, h0 = carry
    x = jnp.swapaxes(x_TxBxD, 0, 1)
    lengths = jnp.full((x.shape[0],), x.shape[1], jnp.int32)
    sizes = {"input_size": x.shape[-1], "hidden_size": self.hidden, "num_layers": 1}
    out = rnn.lstm(x, h0[None], c0[None], self.cudnn_weights(), lengths, **sizes, dropout=0.0, bidirectional=False)
    y, h_n, c_n = cast(tuple, out)
    return (c_n[0], h_n[0]), jnp.swapaxes(y, 0, 1)


class LNLSTMCell(_Cell):
  """Layer-normalized LSTM: LN on the input and recurrent gate pre-activations (separately, per
  gate) and on the cell state, as in Ba, Kiros & Hinton (2016). The input part, LN included,
  depends on x only and is hoisted out of the time loop."""

  num_carries = 2

  def __init__(self, in_features: int, hidden: int, *, forget_bias: float = 1.0, rngs: nnx.Rngs):
    self.hidden = hidden
    self.w_x = _kernel(rngs, (in_features, 4 * hidden), nnx.initializers.glorot_uniform())
    self.w_h = _kernel(rngs, (hidden, 4 * hidden), nnx.initializers.orthogonal())
    self.gain_x = nnx.Param(jnp.ones((4, hidden)))
    self.gain_h = nnx.Param(jnp.ones((4, hidden)))
    # The only gate bias sits after the input LN; the forget gate starts open.
    self.b = nnx.Param(jnp.zeros((4, hidden)).at[1].set(forget_bias))
    self.gain_c = nnx.Param(jnp.ones((hidden,)))
    self.bias_c = nnx.Param(jnp.zeros((hidden,)))

  def project(self, x):
    z = dense(x, self.w_x[...]).reshape(x.shape[:-1] + (4, self.hidden))
    return layer_norm(z, self.gain_x[...], self.b[...]).reshape(x.shape[:-1] + (4 * self.hidden,))

  def loop_params(self):
    return {"gain_h": self.gain_h[...], "gain_c": self.gain_c[...], "bias_c": self.bias_c[...]}

  @staticmethod
  def recurrent_update(loop_params, xp_Bx4H, r_Bx4H, carry):
    c, h, _ = lnlstm_step(
      loop_params["gain_h"], loop_params["gain_c"], loop_params["bias_c"], xp_Bx4H, r_Bx4H, carry[0]
    )
    return (c, h), h

  def scan(self, carry, xp_TxBx4H):
    return lnlstm_scan(self.w_h[...], self.gain_h[...], self.gain_c[...], self.bias_c[...], xp_TxBx4H, *carry)


class GRUCell(_Cell):
  """GRU (gates r, z, candidate n) with the reset gate applied after the recurrent matmul (cuDNN
  and PyTorch convention), so the input part is hoistable."""

  num_carries = 1

  def __init__(self, in_features: int, hidden: int, *, forget_bias: float = 0.0, rngs: nnx.Rngs):
    del forget_bias  # GRUs have no forget gate
    self.hidden = hidden
    self.w_x = _kernel(rngs, (in_features, 3 * hidden), nnx.initializers.glorot_uniform())
    self.w_h = _kernel(rngs, (hidden, 3 * hidden), nnx.initializers.orthogonal())
    self.b_x = nnx.Param(jnp.zeros((3 * hidden,)))
    self.b_h = nnx.Param(jnp.zeros((3 * hidden,)))

  def project(self, x):
    return dense(x, self.w_x[...]) + self.b_x[...]

  def loop_params(self):
    return {"b_h": self.b_h[...]}

  @staticmethod
  def recurrent_update(loop_params, xp_Bx3H, r_Bx3H, carry):
    h, _ = gru_step(loop_params["b_h"], xp_Bx3H, r_Bx3H, carry[0])
    return (h,), h

  def scan(self, carry, xp_TxBx3H):
    return gru_scan(self.w_h[...], self.b_h[...], xp_TxBx3H, *carry)


CELLS = {"lstm": LSTMCell, "lnlstm": LNLSTMCell, "gru": GRUCell}
