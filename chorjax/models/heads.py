"""Output heads: MSE (a point estimate) and MDN (a mixture of Gaussians over the whole frame).

Both heads have the same interface: ``head(h_...xH) -> out_...xP`` (the head's unconstrained
outputs), ``head.loss(out, target) -> (loss, aux)`` and ``head.sample(out, key, ...) -> frame``. For
the MDN, one pure function (``mdn_params``) turns those outputs into (mixture log-weights, means, scales):
scales pass through softplus and are floored at ``min_scale`` so the likelihood stays finite.
"""

from __future__ import annotations

import math
from typing import Any

import jax
import jax.numpy as jnp
from flax import nnx

from chorjax.models.fused import dense


def _linear(layer: nnx.Linear, h):
  """``layer(h)`` through :func:`~chorjax.models.fused.dense` (its faster weight gradient)."""
  assert layer.bias is not None  # the heads' layers have biases
  return dense(h, layer.kernel[...]) + layer.bias[...]


class MSEHead(nnx.Module):
  """Dense layer to the frame; loss = mean squared error over every coordinate."""

  def __init__(self, hidden: int, dim: int, *, rngs: nnx.Rngs):
    self.dim = dim
    self.out = nnx.Linear(hidden, dim, rngs=rngs)

  def __call__(self, h):
    return _linear(self.out, h)

  def loss(self, out_xD, target_xD):
    mse = jnp.mean(jnp.square(out_xD - target_xD))
    return mse, {"mse": mse}

  def sample(self, out_BxD, key, pi_temperature=1.0, sigma_temperature=1.0, greedy=False):
    del key, pi_temperature, sigma_temperature, greedy  # a point estimate has nothing to draw
    return out_BxD

  def draw(self, out_BxD, gumbel_BxK, noise_BxD, state, **_):
    del gumbel_BxK, noise_BxD  # nothing to draw
    return out_BxD, state

  def draw_start(self, x_BxTxD, out_BxTxP=None):
    """The draw's state before the first frame (:meth:`MDNHead.draw_start`'s, which the MSE head keeps)."""
    del out_BxTxP
    b = x_BxTxD.shape[0]
    return jnp.full((b,), -1, jnp.int32), jnp.zeros((b, self.dim), x_BxTxD.dtype)

  def mean(self, out_xD):
    return out_xD


def mdn_params(out_xP, num_mixtures: int, dim: int, isotropic: bool, min_scale: float):
  """Raw head outputs -> ``(logpi_xK, mu_xKxD, scale_xKxS)`` with S = 1 (isotropic) or D (a correlated
  head's coefficients, after these, are :func:`mdn_carry`'s)."""
  k, s = num_mixtures, 1 if isotropic else dim
  assert (out_xP.shape[-1] - (k + k * dim + k * s)) % s == 0, (out_xP.shape, k, dim, s)  # + the carry's
  lead = out_xP.shape[:-1]
  logits, mu, scale = jnp.split(out_xP[..., : k + k * dim + k * s], [k, k + k * dim], axis=-1)
  logpi = jax.nn.log_softmax(logits, axis=-1)
  mu = mu.reshape(lead + (k, dim))
  scale = jnp.maximum(jax.nn.softplus(scale.reshape(lead + (k, s))), min_scale)
  return logpi, mu, scale


def mdn_carry(out_xP, scales: int, memory: int, smooth: bool = False):
  """A head's carry coefficients ``[..., M, 1, S]`` in (-1, 1) (``M = memory``), M per coordinate shared by
  every component: the partial autocorrelations of the residuals (the frame minus a component's mean) at lags
  1 to M, which :func:`ar_coefficients` turns into how much of each earlier frame's residual the components
  carry into this frame's means (:meth:`MDNHead.carried`). Shared, a component the draw switches to continues
  from where the last frame was, as the one it leaves would.

  ``smooth`` (``model.mdn_carry``): the autoregression's polynomial at -1, ``prod_k f_k`` with ``f_k = 1 -
  kappa_k (-1)^k`` in (0, 2), stays at least 1 lag by lag: ``f_k`` is drawn between ``1 / (f_1 ... f_(k-1))``
  and 2. So the residuals gain no power at the highest frequency (a flip of sign every frame), while a lag may
  still take either sign where the others leave room."""
  raw = out_xP[..., -memory * scales :].reshape(out_xP.shape[:-1] + (memory, 1, scales))
  if not smooth:
    return jnp.tanh(raw)
  partial, gain = [], 1.0
  for k in range(memory):
    low = 1.0 / gain
    f = low + (2.0 - low) * jax.nn.sigmoid(raw[..., k, :, :])
    partial.append((1.0 - f) * (-1.0) ** (k + 1))
    gain = gain * f
  return jnp.stack(partial, axis=-3)


def ar_coefficients(partial):
  """Partial autocorrelations ``kappa_1..kappa_M`` (each in (-1, 1)) -> the coefficients ``phi_1..phi_M`` of the
  autoregression ``r_t = sum_k phi_k r_(t-k) + noise`` they describe (the Durbin-Levinson recursion). Whatever
  the network predicts, that autoregression is stationary: a draw's residuals can wander (``phi = (2, -1)``,
  a random walk of the velocity, is the limit ``kappa = (1, -1)``) but never grow without bound."""
  phi: list = []
  for kappa in partial:
    phi = [p - kappa * q for p, q in zip(phi, reversed(phi))] + [kappa]
  return phi


def white_axes(model_cfg, features) -> int:
  """How many of the MDN's last coordinates carry no residuals: with ``model.mdn_memory``, a canonical run's
  foot contacts (its features' last ``len(feet)``, 0/1 flags: carried, their residuals wander without end and
  every foot stays planted or never lands), which the basis keeps as axes of their own
  (``families.recurrent.mdn_basis``); else none."""
  if not model_cfg.memory or model_cfg.mdn_scale == "isotropic" or features.representation != "canonical":
    return 0
  return len(features.skeleton.feet)


def mdn_log_prob(logpi_xK, mu_xKxD, scale_xKxS, x_xD):
  """``log p(x)`` of every frame under the mixture, by logsumexp (finite for tiny scales)."""
  dim = mu_xKxD.shape[-1]
  z = (x_xD[..., None, :] - mu_xKxD) / scale_xKxS
  log_scale = jnp.broadcast_to(jnp.log(scale_xKxS), mu_xKxD.shape).sum(-1)
  comp_xK = -0.5 * jnp.sum(z * z, axis=-1) - log_scale - 0.5 * dim * math.log(2 * math.pi)
  return jax.nn.logsumexp(logpi_xK + comp_xK, axis=-1)


def mdn_sample(key, logpi_BxK, mu_BxKxD, scale_BxKxS, pi_temperature=1.0, sigma_temperature=1.0, greedy: bool = False):
  """Draws one frame per row.

  Args:
    key: PRNG key.
    logpi_BxK, mu_BxKxD, scale_BxKxS: the mixture.
    pi_temperature: divides the mixture logits (< 1 sharpens, 0 = the most likely component).
    sigma_temperature: multiplies the scales (0 = the component mean).
    greedy: the mean of the most likely component (no randomness at all).
  """
  best = jnp.argmax(logpi_BxK, axis=-1)
  if greedy:
    return jnp.take_along_axis(mu_BxKxD, best[:, None, None], axis=1)[:, 0]
  gumbel_BxK, noise_BxD = frame_numbers(key, *mu_BxKxD.shape)
  return mdn_draw(gumbel_BxK, logpi_BxK, mu_BxKxD, scale_BxKxS, noise_BxD, pi_temperature, sigma_temperature)[0]


def frame_numbers(key, batch: int, num_mixtures: int, dim: int):
  """The random numbers one frame is drawn with: ``(standard Gumbel [B, K], standard normal [B, D])`` from the
  two halves of ``key``. Everything else in a draw is a function of them, so a host that brings its own
  (``chorjax export``) draws what chorjax draws."""
  k_comp, k_noise = jax.random.split(key)
  return (
    jax.random.gumbel(k_comp, (batch, num_mixtures), jnp.float32),
    jax.random.normal(k_noise, (batch, dim), jnp.float32),
  )


def mdn_draw(
  gumbel_BxK,
  logpi_BxK,
  mu_BxKxD,
  scale_BxKxS,
  noise_BxD,
  pi_temperature=1.0,
  sigma_temperature=1.0,
  bias_BxK: Any = 0.0,
):
  """One frame per row from the component the standard Gumbel noise ``gumbel_BxK`` picks (the largest tempered
  log-weight plus it: what ``jax.random.categorical`` draws) and the given standard-normal ``noise_BxD``
  (smoothed noise makes smooth motion); ``bias_BxK`` is added to the tempered log-weights (persistence).
  Returns ``(frame [B, D], component [B])``."""
  t = jnp.asarray(pi_temperature, jnp.float32)
  drawn = jnp.argmax(logpi_BxK / jnp.maximum(t, 1e-6) + bias_BxK + gumbel_BxK, axis=-1)
  comp = jnp.where(t > 0, drawn, jnp.argmax(logpi_BxK + bias_BxK, axis=-1))
  mu = jnp.take_along_axis(mu_BxKxD, comp[:, None, None], axis=1)[:, 0]
  scale = jnp.take_along_axis(scale_BxKxS, comp[:, None, None], axis=1)[:, 0]
  return mu + scale * sigma_temperature * noise_BxD, comp


class MDNHead(nnx.Module):
  """Mixture density network over the whole D-dim frame (Graves 2013; chor-rnn).

  Loss = negative log-likelihood per frame (summed over the D coordinates, averaged over frames).

  With ``basis`` (``model.mdn_basis = "pca"`` or ``"acceleration"``) the mixture lives in rotated coordinates
  ``u = x @ B`` (``B``: ``[D, D]`` orthogonal, the principal axes of the training frames or of their second
  differences, set once before training by ``create_train_state`` and never trained): each component is still
  diagonal there, so a full
  covariance in feature space with the data's own axes. ``params`` and the scales ``scale_cap`` holds are
  in those coordinates; what ``loss``, ``sample``, ``draw`` and ``mean`` take and return are features, as
  without it. A rotation keeps the likelihood: the NLL is the same quantity either way. With ``memory``, the
  last ``white`` coordinates carry no residuals (a run's foot contacts, 0/1 flags whose carried residuals
  would wander without end: :func:`white_axes`).
  """

  def __init__(
    self,
    hidden: int,
    dim: int,
    *,
    num_mixtures: int = 8,
    isotropic: bool = False,
    min_scale: float = 1e-3,
    basis: bool = False,
    memory: int = 0,
    white: int = 0,
    smooth: bool = False,
    radius: float = 1.0,
    rngs: nnx.Rngs,
  ):
    self.dim, self.num_mixtures, self.isotropic, self.min_scale = dim, num_mixtures, isotropic, min_scale
    self.memory, self.white, self.smooth, self.radius = memory, white, smooth, radius
    self.out = nnx.Linear(hidden, self.num_outputs, rngs=rngs)
    self.basis = nnx.Param(jnp.eye(dim)) if basis else None  # a Param so checkpoints carry it; never trained

  def _rotation(self):
    return None if self.basis is None else jax.lax.stop_gradient(self.basis[...])

  def to_basis(self, x_xD):
    """Features -> the mixture's coordinates."""
    b = self._rotation()
    return x_xD if b is None else x_xD @ b

  def from_basis(self, u_xD):
    """The mixture's coordinates -> features."""
    b = self._rotation()
    return u_xD if b is None else u_xD @ b.T

  @property
  def num_scales(self) -> int:
    return 1 if self.isotropic else self.dim

  @property
  def num_outputs(self) -> int:
    k = self.num_mixtures
    return k + k * self.dim + k * self.num_scales + self.memory * self.num_scales

  @property
  def correlated(self) -> bool:
    """Whether a frame's means carry the residuals of the frames before (``memory`` > 0)."""
    return self.memory > 0

  def __call__(self, h):
    return _linear(self.out, h)

  def params(self, out):
    return mdn_params(out, self.num_mixtures, self.dim, self.isotropic, self.min_scale)

  def carried(self, out_xP, residuals):
    """The mixture with the residuals of the frames before carried into its means (``correlated``):
    ``residuals``, the ``memory`` latest first, each ``[..., K, D]``; the means are ``mu + phi_1 r + phi_2 r'
    + ...``, a stationary autoregression of the residuals (:func:`ar_coefficients` of the partial
    autocorrelations :func:`mdn_carry` predicts): the model's mean plus where its last residuals were, where
    they were heading and how that was turning. Returns ``(logpi, means, scale)``."""
    logpi, mu, scale = self.params(out_xP)
    partial = jnp.moveaxis(mdn_carry(out_xP, self.num_scales, self.memory, self.smooth), -3, 0)
    if self.white:  # the last axes carry nothing: drawn white about the means
      partial = partial * (jnp.arange(self.num_scales) < self.num_scales - self.white)
    carried = mu
    for lag, (phi, r) in enumerate(zip(ar_coefficients(list(partial)), residuals), 1):
      carried = carried + phi * self.radius**lag * r
    return logpi, carried, scale

  def residual(self, out_xP, u_xD):
    """``u`` (the mixture's coordinates) minus each component's mean: ``[..., K, D]``."""
    return u_xD[..., None, :] - self.params(out_xP)[1]

  def history(self, out_xTxP, u_xTxD):
    """What :meth:`carried` takes at every frame of a window whose outputs ``out`` predicted ``u``: the
    residuals of the ``memory`` frames before, latest first, ``[..., T, K, D]`` each (zeros before the
    window's first frame)."""
    r = self.residual(out_xTxP, u_xTxD)
    pad = lambda n: jnp.concatenate([jnp.zeros_like(r[..., :n, :, :]), r[..., : r.shape[-3] - n, :, :]], axis=-3)
    return tuple(pad(n) for n in range(1, self.memory + 1))

  def loss(self, out_xP, target_xD):
    """The NLL of every frame (``[..., T, P]`` outputs, ``[..., T, D]`` targets). With ``memory``, a frame's
    components carry the residuals of the targets before it (:meth:`history`: none before the window's
    first frame): the likelihood of the frame given everything before it, as the draw continues."""
    target = self.to_basis(target_xD)
    if self.correlated:
      logpi, mu, scale = self.carried(out_xP, self.history(out_xP, target))
    else:
      logpi, mu, scale = self.params(out_xP)
    nll = -jnp.mean(mdn_log_prob(logpi, mu, scale, target))
    # The MSE of the mixture mean: comparable with the MSE head (a rotation keeps it).
    mean = jnp.sum(jnp.exp(logpi)[..., None] * mu, axis=-2)
    return nll, {"nll": nll, "mse": jnp.mean(jnp.square(mean - target)), "min_scale": jnp.min(scale)}

  def sample(self, out_BxP, key, pi_temperature=1.0, sigma_temperature=1.0, greedy=False):
    logpi, mu, scale = self.params(out_BxP)
    return self.from_basis(mdn_sample(key, logpi, mu, scale, pi_temperature, sigma_temperature, greedy))

  def draw(
    self,
    out_BxP,
    gumbel_BxK,
    noise_BxD,
    state,
    *,
    pi_temperature=1.0,
    sigma_temperature=1.0,
    persistence=0.0,
    crossfade=0.0,
    scale_cap=None,
  ):
    """A frame drawn with the given random numbers (:func:`frame_numbers`); ``state`` (:meth:`draw_start`):
    ``(previous component [B] (-1: none), offset [B, D])`` and, ``correlated``, the residuals ``[B, K, D]`` of
    the ``memory`` frames before (latest first), which :meth:`carried` carries into this frame's means.

    ``persistence`` is added to the previous component's log-weight. ``crossfade``: when the component
    changes, the jump between the two components' means is carried into the frame and decays by this
    factor per frame (0 = off), so a switch is a short glide, not a cut. ``scale_cap`` (``[S]`` or None):
    the components' scales are held at most at it. ``noise_BxD``, the offset and ``scale_cap`` are in the
    mixture's coordinates (``basis``); the frame is features. Returns ``(frame, state)``.
    """
    previous_B, offset_BxD, *memory = state
    logpi, mu, scale = self.carried(out_BxP, memory) if self.correlated else self.params(out_BxP)
    if scale_cap is not None:
      scale = jnp.minimum(scale, scale_cap)
    bias = persistence * jax.nn.one_hot(previous_B, self.num_mixtures)
    x, comp = mdn_draw(gumbel_BxK, logpi, mu, scale, noise_BxD, pi_temperature, sigma_temperature, bias)
    mean_of = lambda c: jnp.take_along_axis(mu, jnp.maximum(c, 0)[:, None, None], axis=1)[:, 0]
    switched = ((comp != previous_B) & (previous_B >= 0))[:, None]
    offset_BxD = crossfade * (offset_BxD + jnp.where(switched, mean_of(previous_B) - mean_of(comp), 0.0))
    u = x + offset_BxD
    state = (comp, offset_BxD, *memory)
    return self.from_basis(u), self.remember(state, self.residual(out_BxP, u)) if self.correlated else state

  def remember(self, state, residual_BxKxD):
    """The draw's ``state`` (:meth:`draw`) with ``residual`` the latest of the residuals it carries, the oldest
    forgotten: what a drawn frame leaves (:meth:`draw`), and a frame fed in training (``train.feedback``)."""
    previous_B, offset_BxD, *memory = state
    return (previous_B, offset_BxD, residual_BxKxD, *memory[:-1])

  def draw_start(self, x_BxTxD, out_BxTxP=None):
    """The draw's state before the frame after the frames ``x`` (:meth:`draw`): no component, no offset
    and, ``correlated``, the residuals of ``x``'s last ``memory`` frames from ``out`` (the outputs that predicted
    ``x[:, 1:]``: a prime's), zeros where there are none."""
    b = x_BxTxD.shape[0]
    state = (jnp.full((b,), -1, jnp.int32), jnp.zeros((b, self.dim), x_BxTxD.dtype))
    if not self.correlated:
      return state
    none = jnp.zeros((b, self.memory, self.num_mixtures, self.dim), x_BxTxD.dtype)
    r = none if out_BxTxP is None else self.residual(out_BxTxP, self.to_basis(x_BxTxD[:, 1:]))
    r = jnp.concatenate([none, r], axis=1)  # the frames' residuals, zeros before the first
    return (*state, *[r[:, -1 - i] for i in range(self.memory)])

  def mean(self, out_xP):
    """The mixture's mean frame."""
    logpi, mu, _ = self.params(out_xP)
    return self.from_basis(jnp.sum(jnp.exp(logpi)[..., None] * mu, axis=-2))
