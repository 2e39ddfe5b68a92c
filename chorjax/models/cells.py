"""Single-step recurrent cells: LSTM, layer-normalized LSTM (Ba et al. 2016) and GRU.

Every cell splits one frame's work in three so that training and sampling share one code path and
training can be fast:

* ``project(x_...xD) -> xp_...xG``: everything that depends on the input only. Training applies it
  to a whole window at once (one large matmul, hoisted out of the time loop).
* the recurrent matmul ``r = h @ w_h`` (the only work that must stay inside the loop);
* ``post(small, xp_BxG, r_BxG, carry) -> (carry, h_BxH)``: pure elementwise work (gates, layer
  norms), with ``small`` the cell's small parameters.

``step(carry, xp)`` = ``post(small, xp, h @ w_h, carry)`` is what sampling calls once per frame and
what training scans over a window. (Keeping the elementwise part separate from the one in-loop
matmul leaves room for a custom backward pass; one was tried and measured, see BENCHMARKS.md.)
A carry is a tuple of ``[B, H]`` arrays whose LAST entry is h: ``(c, h)`` for the LSTMs, ``(h,)``
for the GRU.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import nnx

_LN_EPS = 1e-5


def _kernel(rngs, shape, init):
  return nnx.Param(init(rngs.params(), shape, jnp.float32))


def _layer_norm(x_xGxH, gain_GxH, bias_GxH=None):
  """Normalizes the last axis (of every gate separately, for ``[..., G, H]`` inputs)."""
  mean = x_xGxH.mean(-1, keepdims=True)
  var = jnp.square(x_xGxH - mean).mean(-1, keepdims=True)
  y = (x_xGxH - mean) * jax.lax.rsqrt(var + _LN_EPS) * gain_GxH
  return y if bias_GxH is None else y + bias_GxH


class _Cell(nnx.Module):
  def small(self) -> dict:
    """The small parameters ``post`` needs (biases and gains inside the loop)."""
    return {}

  def step(self, carry, xp_BxG):
    return self.post(self.small(), xp_BxG, carry[-1] @ self.w_h[...], carry)


class LSTMCell(_Cell):
  """LSTM (gates i, f, g, o); forget-gate bias initialized to ``forget_bias``."""

  num_carries = 2

  def __init__(self, in_features: int, hidden: int, *, forget_bias: float = 1.0, rngs: nnx.Rngs):
    self.hidden = hidden
    self.w_x = _kernel(rngs, (in_features, 4 * hidden), nnx.initializers.glorot_uniform())
    self.w_h = _kernel(rngs, (hidden, 4 * hidden), nnx.initializers.orthogonal())
    self.b = nnx.Param(jnp.zeros((4 * hidden,)).at[hidden:2 * hidden].set(forget_bias))

  def project(self, x):
    return x @ self.w_x[...] + self.b[...]

  @staticmethod
  def post(small, xp_Bx4H, r_Bx4H, carry):
    c, _ = carry
    i, f, g, o = jnp.split(xp_Bx4H + r_Bx4H, 4, axis=-1)
    c = jax.nn.sigmoid(f) * c + jax.nn.sigmoid(i) * jnp.tanh(g)
    h = jax.nn.sigmoid(o) * jnp.tanh(c)
    return (c, h), h


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
    z = (x @ self.w_x[...]).reshape(x.shape[:-1] + (4, self.hidden))
    return _layer_norm(z, self.gain_x[...], self.b[...]).reshape(x.shape[:-1] + (4 * self.hidden,))

  def small(self):
    return {"gain_h": self.gain_h[...], "gain_c": self.gain_c[...], "bias_c": self.bias_c[...]}

  @staticmethod
  def post(small, xp_Bx4H, r_Bx4H, carry):
    c, _ = carry
    hidden = small["gain_c"].shape[-1]
    zh = r_Bx4H.reshape(r_Bx4H.shape[:-1] + (4, hidden))
    z = xp_Bx4H.reshape(zh.shape) + _layer_norm(zh, small["gain_h"])
    i, f, g, o = (z[..., k, :] for k in range(4))
    c = jax.nn.sigmoid(f) * c + jax.nn.sigmoid(i) * jnp.tanh(g)
    h = jax.nn.sigmoid(o) * jnp.tanh(_layer_norm(c, small["gain_c"], small["bias_c"]))
    return (c, h), h


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
    return x @ self.w_x[...] + self.b_x[...]

  def small(self):
    return {"b_h": self.b_h[...]}

  @staticmethod
  def post(small, xp_Bx3H, r_Bx3H, carry):
    (h,) = carry
    xr, xz, xn = jnp.split(xp_Bx3H, 3, axis=-1)
    hr, hz, hn = jnp.split(r_Bx3H + small["b_h"], 3, axis=-1)
    r = jax.nn.sigmoid(xr + hr)
    z = jax.nn.sigmoid(xz + hz)
    n = jnp.tanh(xn + r * hn)
    h = (1.0 - z) * n + z * h
    return (h,), h


CELLS = {"lstm": LSTMCell, "lnlstm": LNLSTMCell, "gru": GRUCell}
