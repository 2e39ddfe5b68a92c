"""Tang et al. 2022 ("Real-time Controllable Motion Transition for Characters"), on joint positions:
``inbetween.system = "cvae"``.

Poses are flat local positions ``[K = 3J]`` in leg lengths (``chorjax.inbetween.Space``). The manifold
works on the pose relative to the root's floor point (``split``): a frame is that relative pose plus the
root's floor point, which moves by the root's step.

* Stage 1, the motion manifold (:class:`Manifold`): a conditional VAE of the next frame given the previous
  one. Its encoder (ELU layers) reads the next and previous relative poses and the previous step and
  gives ``(mu, log var)`` of ``z``; its decoder is a mixture of experts: a gating network (ELU layers, a
  softmax) weighs ``experts`` expert networks (ELU layers), each given the previous relative pose and
  step, with ``z`` and the root's step to the next frame fed to every one of their layers (against
  posterior collapse); the blend is the next relative pose's change.
* Stage 2, the transition sampler (:class:`Sampler`): encoders of the current state, the offset to the
  target and the target (with the time-to-arrival embedding added, as the Harvey model), an LSTM (the
  recurrent core, ``model.*``) and a prior decoder that writes ``z`` (mean and log variance: a draw, so
  seeds differ) and the root's step for the frozen manifold decoder.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import nnx

from chorjax.families.inbetween.lstm_model import MLP, TransitionModel, add_encoders_and_core, encode_step
from chorjax.models.rnn import RecurrentCore

POSE_GAIN, STEP_GAIN, OFFSET_GAIN, OUT_SCALE = 2.0, 50.0, 4.0, 0.02  # inputs / output at about unit size


def split(x_BxK, root: int):
  """``(relative pose [B, K], root floor point [B, 3])``: the pose with the root's floor point removed."""
  pos = x_BxK.reshape(*x_BxK.shape[:-1], -1, 3)
  floor = pos[..., root, :] * jnp.array([1.0, 0.0, 1.0])
  return (pos - floor[..., None, :]).reshape(x_BxK.shape), floor


def join(rel_BxK, floor_Bx3):
  pos = rel_BxK.reshape(*rel_BxK.shape[:-1], -1, 3) + floor_Bx3[..., None, :]
  return pos.reshape(rel_BxK.shape)


class Expert(nnx.Module):
  """ELU layers with ``cond`` (z and the root's step) concatenated to the input of every layer."""

  def __init__(self, in_size: int, cond: int, sizes, out: int, *, rngs: nnx.Rngs):
    dims = (in_size, *sizes)
    self.hidden = nnx.List([nnx.Linear(dims[i] + cond, dims[i + 1], rngs=rngs) for i in range(len(sizes))])
    self.out = nnx.Linear(dims[-1] + cond, out, rngs=rngs)

  def __call__(self, x, cond):
    for layer in self.hidden:
      x = jax.nn.elu(layer(jnp.concatenate([x, cond], -1)))
    return self.out(jnp.concatenate([x, cond], -1))


class Manifold(nnx.Module):
  """The conditional VAE: ``encode(next, prev, step) -> (mu, logvar)``, ``decode(z, prev, step, root step)``."""

  def __init__(self, ib, dim: int, *, rngs: nnx.Rngs):
    self.latent = ib.latent_size
    enc = tuple(ib.manifold_encoder_sizes)
    self.encoder = MLP((3 * dim, *enc), rngs=rngs)
    self.to_latent = nnx.Linear(enc[-1], 2 * self.latent, rngs=rngs)
    cond = self.latent + 3
    self.gate = MLP((2 * dim + cond, *ib.gate_sizes, ib.experts), last_act=False, rngs=rngs)
    self.experts = nnx.List([Expert(2 * dim, cond, ib.expert_sizes, dim, rngs=rngs) for _ in range(ib.experts)])

  def encode(self, next_rel, prev_rel, prev_step):
    change = STEP_GAIN * (next_rel - prev_rel)  # what z is to tell: the pose's change, at about unit size
    h = self.encoder(jnp.concatenate([change, POSE_GAIN * prev_rel, STEP_GAIN * prev_step], -1))
    mu, logvar = jnp.split(self.to_latent(h), 2, -1)
    # the posterior starts narrow (sigma ~0.05): with unit noise at first the decoder learns to ignore z
    # (measured: KL 0.4-0.7 nats by step 750, the posterior collapsed)
    return mu, jnp.clip(logvar - 6.0, -12.0, 5.0)

  def decode(self, z, prev_rel, prev_step, root_step_Bx3):
    """The next relative pose ``[B, K]`` and the gate's weights ``[B, experts]``."""
    x = jnp.concatenate([POSE_GAIN * prev_rel, STEP_GAIN * prev_step], -1)
    cond = jnp.concatenate([z, STEP_GAIN * root_step_Bx3], -1)
    weights = jax.nn.softmax(self.gate(jnp.concatenate([x, cond], -1)), -1)
    outs = jnp.stack([e(x, cond) for e in self.experts], -1)  # [B, K, experts]
    return prev_rel + OUT_SCALE * jnp.einsum("bke,be->bk", outs, weights), weights


class Sampler(nnx.Module):
  """Stage 2: ``step(carry, rel, step, offset, target_rel, tta) -> (carry, mu, logvar, root step)``."""

  core: RecurrentCore  # with width and the three encoders: add_encoders_and_core

  def __init__(self, model_cfg, ib, dim: int, *, rngs: nnx.Rngs):
    self.latent = ib.latent_size
    add_encoders_and_core(self, model_cfg, ib.encoder_sizes, dim, rngs)
    self.prior = MLP((model_cfg.hidden_size, *ib.decoder_sizes, 2 * self.latent + 3), last_act=False, rngs=rngs)

  def initial_carry(self, batch: int):
    return self.core.initial_carry(jnp.zeros((batch, 1), jnp.float32))

  def step(self, carry, rel, prev_step, offset, target_rel, tta_B):
    state = jnp.concatenate([POSE_GAIN * rel, STEP_GAIN * prev_step], -1)
    carry, h = encode_step(self, carry, state, OFFSET_GAIN * offset, POSE_GAIN * target_rel, tta_B)
    out = self.prior(h)
    mu, logvar, root = out[:, : self.latent], out[:, self.latent : 2 * self.latent], out[:, 2 * self.latent :]
    return carry, mu, jnp.clip(logvar, -10.0, 5.0), root / STEP_GAIN


class TransitionCVAE(nnx.Module):
  """Both stages in one module (one checkpoint): ``manifold`` and ``sampler``."""

  def __init__(self, model_cfg, ib, dim: int, root: int, *, rngs: nnx.Rngs):
    self.root = root
    self.manifold = Manifold(ib, dim, rngs=rngs)
    self.sampler = Sampler(model_cfg, ib, dim, rngs=rngs)


def manifold_rollout(manifold: Manifold, window_BxWxK, start: int, frames: int, p_own, key, root: int):
  """Stage 1 over ``frames`` frames from frame ``start`` of real windows: each frame encoded with the real
  next frame (the posterior), decoded from the previous frame, which is the model's own with probability
  ``p_own`` (scheduled sampling), else the real one; the root's steps are the real ones.
  ``(frames [B, frames, K], mu, logvar [B, frames, latent], gate weights [B, frames, experts])``."""
  real = jnp.swapaxes(window_BxWxK, 0, 1)  # [W, B, K]
  k_z, k_own = jax.random.split(key)

  def body(carry, t):
    prev, prev2 = carry
    prev_rel, prev_floor = split(prev, root)
    next_rel, next_floor = split(real[t], root)
    prev_step = prev - prev2
    mu, logvar = manifold.encode(next_rel, prev_rel, prev_step)
    eps = jax.random.normal(jax.random.fold_in(k_z, t), mu.shape)
    z = mu + jnp.exp(0.5 * logvar) * eps
    rel, weights = manifold.decode(z, prev_rel, prev_step, next_floor - prev_floor)
    frame = join(rel, next_floor)
    own = jax.random.bernoulli(jax.random.fold_in(k_own, t), p_own, (frame.shape[0], 1))
    fed = jnp.where(own, jax.lax.stop_gradient(frame), real[t])
    return (fed, prev), (frame, mu, logvar, weights)

  steps = jnp.arange(start, start + frames)
  _, (out, mu, logvar, weights) = jax.lax.scan(body, (real[start - 1], real[start - 2]), steps)
  return tuple(jnp.swapaxes(a, 0, 1) for a in (out, mu, logvar, weights))


def sampler_rollout(model: TransitionCVAE, context_BxCxK, target_BxK, length_B, frames: int, key, noise: float = 1.0):
  """Stage 2: the ``frames`` frames after the context, written by the frozen manifold decoder from the
  sampler's latents (``mu + noise * sigma * eps``) and root steps; the context is fed in as it is."""
  b, c, _ = context_BxCxK.shape
  root, length = model.root, length_B.astype(jnp.float32)
  fed = jnp.swapaxes(context_BxCxK, 0, 1)
  target_rel, _ = split(target_BxK, root)

  def body(carry, s):
    core, prev, prev2 = carry
    prev_rel, prev_floor = split(prev, root)
    prev_step = prev - prev2
    tta = (c + length) - s
    core, mu, logvar, root_step = model.sampler.step(core, prev_rel, prev_step, target_BxK - prev, target_rel, tta)
    z = mu + noise * jnp.exp(0.5 * logvar) * jax.random.normal(jax.random.fold_in(key, s), mu.shape)
    rel, _ = model.manifold.decode(z, prev_rel, prev_step, root_step)
    frame = join(rel, prev_floor + root_step * jnp.array([1.0, 0.0, 1.0]))
    nxt = jnp.where(s < c, fed[jnp.minimum(s, c - 1)], frame)
    return (core, nxt, prev), (frame, mu, logvar)

  first = context_BxCxK[:, 0]
  _, (out, mu, logvar) = jax.lax.scan(body, (model.sampler.initial_carry(b), first, first), jnp.arange(1, c + frames))
  return tuple(jnp.swapaxes(a[c - 1 :], 0, 1) for a in (out, mu, logvar))


def transition_model(cfg, features) -> TransitionModel | TransitionCVAE:
  """The in-betweening model of ``inbetween.system`` for ``features``; parameters drawn from ``train.seed``. It
  works on flat joint positions (``3J`` numbers), not on the features."""
  dim, rngs = 3 * features.skeleton.num_joints, nnx.Rngs(cfg.train.seed)
  if cfg.inbetween.system == "cvae":
    return TransitionCVAE(cfg.model, cfg.inbetween, dim, features.skeleton.root, rngs=rngs)
  return TransitionModel(cfg.model, cfg.inbetween, dim, rngs=rngs)
