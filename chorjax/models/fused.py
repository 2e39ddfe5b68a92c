"""Fused LSTM, LN-LSTM and GRU layers for training: one forward scan and a hand-written backward scan.

``jax.grad`` of a plain ``lax.scan`` over the LSTM step works, but on CPU it is slow in ways that add
up over ``layers x frames`` loop iterations: the forward loop stores a dozen separate residuals per
step, and the reverse loop runs many small elementwise kernels and a second, per-step matmul for the
recurrent weight gradient. :func:`lstm_scan` keeps exactly three stacks (the gate activations, the
cell state and the output), computes every gate gradient in one elementwise pass, keeps one matmul in
the reverse loop (``dz @ w_h.T``), and computes the recurrent weight gradient after the loop as one
large matmul. Its loops work in place on one ``[T, B, 4H]`` buffer: the gate activations overwrite the
input projections row by row, and the gate gradients the activations (no zero-filled stack of that
size). :func:`lnlstm_scan` does the same for the layer-normalized LSTM, whose layer-norm gains also get
their gradients after the loop, and :func:`gru_scan` for the GRU (whose stacks are of other widths
than its projections, so it keeps a stack each). Tests check them against the straightforward scan
(outputs and gradients to 1e-5); BENCHMARKS.md has the timings. :func:`dense` is the input
projections' and the heads' matmul with the same kind of backward pass.

Being ``jax.custom_vjp`` functions they support reverse-mode differentiation (``jax.grad``,
``jax.vjp``, ``jax.jacrev``) and ``vmap``, not forward mode (``jax.jvp``, ``jax.jacfwd``); a
``lax.scan`` of a cell's ``step`` does both.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

LN_EPS = 1e-5


def normalize(x):
  """``((x - mean) / std, 1 / std)`` over the last axis."""
  mean = x.mean(-1, keepdims=True)
  rstd = jax.lax.rsqrt(jnp.square(x - mean).mean(-1, keepdims=True) + LN_EPS)
  return (x - mean) * rstd, rstd


@jax.custom_vjp
def dense(x, w):
  """``x @ w`` over any leading axes of ``x``. Its weight gradient is one ``x^T d`` matmul over the
  flattened leading axes: under JAX's own rule XLA:CPU copies the (large) output gradient into a
  transposed layout first and transposes the result back (what that costs: ``docs/perf-notes.md``)."""
  return x @ w


def _dense_fwd(x, w):
  return x @ w, (x, w)


def _dense_bwd(res, d):
  x, w = res
  return d @ w.T, x.reshape(-1, x.shape[-1]).T @ d.reshape(-1, d.shape[-1])


dense.defvjp(_dense_fwd, _dense_bwd)


def layer_norm(x, gain, bias=None):
  """Layer norm over the last axis (of every gate separately, for ``[..., G, H]`` inputs)."""
  y = normalize(x)[0] * gain
  return y if bias is None else y + bias


def _normalize_bwd(dn, n, rstd):
  """The gradient of :func:`normalize`'s input from the gradient of its output ``n``."""
  return rstd * (dn - dn.mean(-1, keepdims=True) - n * (dn * n).mean(-1, keepdims=True))


def _previous(first_BxH, stack_TxBxH):
  """The stack shifted one step back in time: ``[first, stack[0], ..., stack[T-2]]``."""
  return jnp.concatenate([first_BxH[None], stack_TxBxH[:-1]], 0)


def _gate_grads(a_Bx4H, dc_BxH, c_prev_BxH, dh_squashed_BxH):
  """The gradient of the LSTM gate pre-activations ``[i, f, g, o]`` from the gate activations, the
  cell-state gradient and ``dh * squash(c)`` (the output gate's input)."""
  i, f, g, o = jnp.split(a_Bx4H, 4, axis=-1)
  return jnp.concatenate(
    [
      dc_BxH * g * i * (1.0 - i),
      dc_BxH * c_prev_BxH * f * (1.0 - f),
      dc_BxH * i * (1.0 - g * g),
      dh_squashed_BxH * o * (1.0 - o),
    ],
    -1,
  )


def lstm_gates(z_Bx4H):
  """``[sigmoid(i), sigmoid(f), tanh(g), sigmoid(o)]`` of the pre-activations, in one elementwise pass
  (``tanh(x) = 2 sigmoid(2x) - 1``)."""
  hidden = z_Bx4H.shape[-1] // 4
  m = jnp.concatenate(
    [jnp.ones((2 * hidden,), z_Bx4H.dtype), jnp.full((hidden,), 2.0, z_Bx4H.dtype), jnp.ones((hidden,), z_Bx4H.dtype)]
  )
  return jax.nn.sigmoid(z_Bx4H * m) * m - (m - 1.0)


def lstm_update(a_Bx4H, c_BxH, squash=jnp.tanh):
  """The new ``(c, h)`` from gate activations and the previous cell state: ``h = o * squash(c)``."""
  i, f, g, o = jnp.split(a_Bx4H, 4, axis=-1)
  c = f * c_BxH + i * g
  return c, o * squash(c)


def _row(stack, t):
  """``stack[t]`` for a traced ``t``."""
  return jax.lax.dynamic_index_in_dim(stack, t, 0, keepdims=False)


def _set_row(stack, t, row):
  """``stack.at[t].set(row)`` for a traced ``t`` (in place inside a loop)."""
  return jax.lax.dynamic_update_index_in_dim(stack, row, t, 0)


def _next_row(stack, t):
  """``stack[t + 1]`` (the last row for the last ``t``): in a forward loop, read after writing row ``t``."""
  return _row(stack, jnp.minimum(t + 1, stack.shape[0] - 1))


def _previous_row(stack, t):
  """``stack[t - 1]`` (the first row for ``t = 0``): in a reverse loop, read after writing row ``t``."""
  return _row(stack, jnp.maximum(t - 1, 0))


def _forward(w_h, xp_TxBx4H, c0, h0):
  """The LSTM over the input projections: ``((c_T, h_T), (hs, cs, acts))``. The gate activations
  overwrite the projections row by row, so the layer's one ``[T, B, 4H]`` buffer serves both (no
  zero-filled stack of activations). Each step reads the next step's row from the buffer after writing
  its own: a read before the write would make XLA copy the whole buffer every step."""
  frames = xp_TxBx4H.shape[0]
  hs = jnp.zeros(xp_TxBx4H.shape[:-1] + h0.shape[-1:], xp_TxBx4H.dtype)

  def body(t, state):
    c, h, xp_t, acts, hs, cs = state
    a = lstm_gates(xp_t + h @ w_h)
    c, h = lstm_update(a, c)
    acts = _set_row(acts, t, a)
    return c, h, _next_row(acts, t), acts, _set_row(hs, t, h), _set_row(cs, t, c)

  init = (c0, h0, xp_TxBx4H[0], xp_TxBx4H, hs, jnp.zeros_like(hs))
  c, h, _, acts, hs, cs = jax.lax.fori_loop(0, frames, body, init)
  return (c, h), (hs, cs, acts)


@jax.custom_vjp
def lstm_scan(w_h, xp_TxBx4H, c0, h0):
  """Runs an LSTM over precomputed input projections ``xp = x @ w_x + b`` (time-major):
  ``((c_T, h_T), h_TxBxH)``."""
  carry, (hs, _, _) = _forward(w_h, xp_TxBx4H, c0, h0)
  return carry, hs


def _lstm_scan_fwd(w_h, xp_TxBx4H, c0, h0):
  carry, (hs, cs, acts) = _forward(w_h, xp_TxBx4H, c0, h0)
  return (carry, hs), (w_h, c0, h0, hs, cs, acts)


def _lstm_scan_bwd(res, cotangents):
  w_h, c0, h0, hs, cs, acts = res
  (dc_last, dh_last), dhs = cotangents
  w_hT = w_h.T
  frames = hs.shape[0]

  # The gate gradients overwrite the activations row by row, as the forward's activations did the
  # projections; the cell state read at step t is the one step t + 1 read as its predecessor.
  def body(i, state):
    dc_next, dh_next, a, c, dz_TxBx4H = state
    t = frames - 1 - i
    cp = jnp.where(t == 0, c0, _previous_row(cs, t))
    _, f, _, o = jnp.split(a, 4, axis=-1)
    tc = jnp.tanh(c)
    dh = _row(dhs, t) + dh_next
    dc = dc_next + dh * o * (1.0 - tc * tc)
    dz = _gate_grads(a, dc, cp, dh * tc)
    dz_TxBx4H = _set_row(dz_TxBx4H, t, dz)
    return dc * f, dz @ w_hT, _previous_row(dz_TxBx4H, t), cp, dz_TxBx4H

  init = (dc_last, dh_last, acts[-1], cs[-1], acts)
  dc0, dh0, _, _, dz_TxBx4H = jax.lax.fori_loop(0, frames, body, init)
  dw_h = jnp.einsum("tbh,tbg->hg", _previous(h0, hs), dz_TxBx4H)
  return dw_h, dz_TxBx4H, dc0, dh0


lstm_scan.defvjp(_lstm_scan_fwd, _lstm_scan_bwd)


def lnlstm_step(gain_h, gain_c, bias_c, xp_Bx4H, r_Bx4H, c_BxH):
  """One LN-LSTM step from the input part ``xp`` (already normalized) and ``r = h @ w_h``:
  ``(c, h, (a, n_h, rstd_h))`` with the gate activations and the normalized ``r`` for the backward."""
  hidden = c_BxH.shape[-1]
  n_h, rstd_h = normalize(r_Bx4H.reshape(r_Bx4H.shape[:-1] + (4, hidden)))
  a = lstm_gates(xp_Bx4H + (n_h * gain_h).reshape(xp_Bx4H.shape))
  c, h = lstm_update(a, c_BxH, lambda c: jnp.tanh(layer_norm(c, gain_c, bias_c)))
  return c, h, (a, n_h, rstd_h)


def _ln_forward(w_h, gain_h, gain_c, bias_c, xp_TxBx4H, c0, h0):
  """The LN-LSTM over the normalized input parts, as :func:`_forward` (the activations overwrite the
  inputs): ``((c_T, h_T), (hs, cs, acts, n_hs, rstd_hs))``."""
  frames, hidden = xp_TxBx4H.shape[0], h0.shape[-1]
  hs = jnp.zeros(xp_TxBx4H.shape[:-1] + (hidden,), xp_TxBx4H.dtype)
  n_hs = jnp.zeros(xp_TxBx4H.shape[:-1] + (4, hidden), xp_TxBx4H.dtype)
  rstd_hs = jnp.zeros(xp_TxBx4H.shape[:-1] + (4, 1), xp_TxBx4H.dtype)

  def body(t, state):
    c, h, xp_t, acts, *stacks = state
    c, h, (a, n_h, rstd_h) = lnlstm_step(gain_h, gain_c, bias_c, xp_t, h @ w_h, c)
    acts = _set_row(acts, t, a)
    stacks = [_set_row(stack, t, row) for stack, row in zip(stacks, (h, c, n_h, rstd_h), strict=True)]
    return c, h, _next_row(acts, t), acts, *stacks

  init = (c0, h0, xp_TxBx4H[0], xp_TxBx4H, hs, jnp.zeros_like(hs), n_hs, rstd_hs)
  c, h, _, acts, hs, cs, n_hs, rstd_hs = jax.lax.fori_loop(0, frames, body, init)
  return (c, h), (hs, cs, acts, n_hs, rstd_hs)


@jax.custom_vjp
def lnlstm_scan(w_h, gain_h, gain_c, bias_c, xp_TxBx4H, c0, h0):
  """Runs a layer-normalized LSTM over precomputed (normalized) input parts, time-major:
  ``((c_T, h_T), h_TxBxH)``."""
  carry, (hs, *_) = _ln_forward(w_h, gain_h, gain_c, bias_c, xp_TxBx4H, c0, h0)
  return carry, hs


def _lnlstm_scan_fwd(w_h, gain_h, gain_c, bias_c, xp_TxBx4H, c0, h0):
  carry, (hs, cs, acts, n_hs, rstd_hs) = _ln_forward(w_h, gain_h, gain_c, bias_c, xp_TxBx4H, c0, h0)
  return (carry, hs), (w_h, gain_h, gain_c, bias_c, c0, h0, hs, cs, acts, n_hs, rstd_hs)


def _lnlstm_scan_bwd(res, cotangents):
  w_h, gain_h, gain_c, bias_c, c0, h0, hs, cs, acts, n_hs, rstd_hs = res
  (dc_last, dh_last), dhs = cotangents
  w_hT = w_h.T
  frames = hs.shape[0]

  # A scan as before (its per-step inputs), plus the gate gradients overwriting the activations as in
  # _lstm_scan_bwd. (A loop that also reads the stacks by index runs as fast but rounds the layer-norm
  # gradients differently: XLA fuses the step's kernels in another way.)
  def body(carry, inputs):
    dc_next, dh_next, a, t, dz_TxBx4H = carry
    dh_out, c, cp, n_h, rstd_h = inputs
    _, f, _, o = jnp.split(a, 4, axis=-1)
    n_c, rstd_c = normalize(c)
    tl = jnp.tanh(n_c * gain_c + bias_c)
    dh = dh_out + dh_next
    dln_c = dh * o * (1.0 - tl * tl)
    dc = dc_next + _normalize_bwd(dln_c * gain_c, n_c, rstd_c)
    dz = _gate_grads(a, dc, cp, dh * tl)
    dr = _normalize_bwd(dz.reshape(n_h.shape) * gain_h, n_h, rstd_h).reshape(dz.shape)
    dz_TxBx4H = _set_row(dz_TxBx4H, t, dz)
    return (dc * f, dr @ w_hT, _previous_row(dz_TxBx4H, t), t - 1, dz_TxBx4H), (dr, dln_c)

  init = (dc_last, dh_last, acts[-1], jnp.asarray(frames - 1), acts)
  (dc0, dh0, _, _, dz), (dr, dln_c) = jax.lax.scan(
    body, init, (dhs, cs, _previous(c0, cs), n_hs, rstd_hs), reverse=True
  )
  dw_h = jnp.einsum("tbh,tbg->hg", _previous(h0, hs), dr)
  dgain_h = jnp.einsum("tbkh,tbkh->kh", dz.reshape(n_hs.shape), n_hs)
  dgain_c = jnp.einsum("tbh,tbh->h", dln_c, normalize(cs)[0])
  return dw_h, dgain_h, dgain_c, dln_c.sum((0, 1)), dz, dc0, dh0


lnlstm_scan.defvjp(_lnlstm_scan_fwd, _lnlstm_scan_bwd)


def gru_step(b_h, xp_Bx3H, r_Bx3H, h_BxH):
  """One GRU step (reset gate after the recurrent matmul, as in cuDNN and PyTorch) from the input part
  ``xp`` and ``r = h @ w_h``: ``(h, (reset, update, candidate, recurrent candidate part))``."""
  hidden = h_BxH.shape[-1]
  rh = r_Bx3H + b_h
  gates = jax.nn.sigmoid(xp_Bx3H[..., : 2 * hidden] + rh[..., : 2 * hidden])
  reset, update = gates[..., :hidden], gates[..., hidden:]
  hn = rh[..., 2 * hidden :]
  n = jnp.tanh(xp_Bx3H[..., 2 * hidden :] + reset * hn)
  return (1.0 - update) * n + update * h_BxH, (reset, update, n, hn)


def _gru_forward(w_h, b_h, xp_TxBx3H, h0):
  def body(h, xp_t):
    h, parts = gru_step(b_h, xp_t, h @ w_h, h)
    return h, (h, jnp.concatenate(parts, -1))

  return jax.lax.scan(body, h0, xp_TxBx3H)


@jax.custom_vjp
def gru_scan(w_h, b_h, xp_TxBx3H, h0):
  """Runs a GRU over precomputed input projections, time-major: ``((h_T,), h_TxBxH)``."""
  h, (hs, _) = _gru_forward(w_h, b_h, xp_TxBx3H, h0)
  return (h,), hs


def _gru_scan_fwd(w_h, b_h, xp_TxBx3H, h0):
  h, (hs, parts) = _gru_forward(w_h, b_h, xp_TxBx3H, h0)
  return ((h,), hs), (w_h, h0, hs, parts)


def _gru_scan_bwd(res, cotangents):
  w_h, h0, hs, parts = res
  (dh_last,), dhs = cotangents
  w_hT = w_h.T
  h_prev = _previous(h0, hs)

  def body(dh_next, inputs):
    dh_out, p, hp = inputs
    reset, update, n, hn = jnp.split(p, 4, axis=-1)
    dh = dh_out + dh_next
    dn = dh * (1.0 - update) * (1.0 - n * n)
    dreset = dn * hn * reset * (1.0 - reset)
    dupdate = dh * (hp - n) * update * (1.0 - update)
    dxp = jnp.concatenate([dreset, dupdate, dn], -1)
    dr = jnp.concatenate([dreset, dupdate, dn * reset], -1)
    return dh * update + dr @ w_hT, (dxp, dr)

  dh0, (dxp, dr) = jax.lax.scan(body, dh_last, (dhs, parts, h_prev), reverse=True)
  return jnp.einsum("tbh,tbg->hg", h_prev, dr), dr.sum((0, 1)), dxp, dh0


gru_scan.defvjp(_gru_scan_fwd, _gru_scan_bwd)
