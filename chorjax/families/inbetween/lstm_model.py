"""The in-betweening family's transition model (``model.family = "inbetween"``, ``inbetween.system = "lstm"``).

A recurrent transition model in the manner of Harvey et al. 2020 ("Robust Motion In-betweening"), over
poses in a window's own local frame (see ``chorjax.inbetween``: flat ``[K = 3J]`` joint positions in leg
lengths, the origin under the root at the last context frame, that frame facing +z).

Every frame ``s`` is written from frame ``s - 1`` by one step: three ELU encoders read the state (the
previous frame's deviation from the linear interpolation between the last context frame and the target,
and its velocity), the offset from the previous frame to the target, and the target; a sinusoidal
embedding of the time to arrival is added to each encoding (Harvey's ``z_tta``), and a noise vector drawn
once per transition to the offset and target encodings (``z_target``), fading out over the last 30 to 5
frames. The existing recurrent core (``model.cell``: LSTM or LN-LSTM) runs over the three encodings, and
a decoder writes the frame's deviation from the linear interpolation (the parametrization of Oreshkin et
al. 2022, "Motion Inbetweening via Deep Delta-Interpolator"). The decoder's output layer starts at zero,
so an untrained model IS linear interpolation and training can only learn what interpolation misses.

The context frames run through the same steps (their own frames fed in, teacher forced), which warms
the core's state; from the last context frame on the model feeds itself its own frames.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import nnx

from chorjax.models.rnn import RecurrentCore

TTA_NOISE_FULL, TTA_NOISE_NONE = 30.0, 5.0  # z_target at full strength this many frames before arrival, none at 5
# Inputs and output brought to about unit size (measured on cmu94 at 30 fps, in leg lengths: a frame's step has
# std 0.02, a transition frame's deviation from interpolation 0.1, the offset to the target 0.26)
DEVIATION_GAIN, VELOCITY_GAIN, OFFSET_GAIN, OUTPUT_SCALE = 10.0, 50.0, 4.0, 0.1


def tta_embedding(tta_B, dim: int, base: float = 10000.0):
  """``[B, dim]`` sinusoidal embedding of the time to arrival (frames), as a transformer's positions."""
  half = jnp.arange(dim // 2, dtype=jnp.float32)
  angle = tta_B[:, None].astype(jnp.float32) / base ** (2.0 * half / dim)
  emb = jnp.stack([jnp.sin(angle), jnp.cos(angle)], -1).reshape(tta_B.shape[0], -1)
  return jnp.pad(emb, ((0, 0), (0, dim - emb.shape[1])))


def noise_strength(tta_B):
  """How much of ``z_target`` a step sees: 1 from 30 frames before arrival, fading to 0 at 5."""
  return jnp.clip((tta_B - TTA_NOISE_NONE) / (TTA_NOISE_FULL - TTA_NOISE_NONE), 0.0, 1.0)


class MLP(nnx.Module):
  """Dense layers with ELU between (and after the last one when ``last_act``); ``zero_last``: the last
  layer's weights and bias start at zero."""

  def __init__(self, sizes, *, last_act: bool = True, zero_last: bool = False, rngs: nnx.Rngs):
    n = len(sizes) - 1
    init = lambda i: nnx.initializers.zeros_init() if zero_last and i == n - 1 else nnx.initializers.lecun_normal()
    self.layers = nnx.List([nnx.Linear(sizes[i], sizes[i + 1], kernel_init=init(i), rngs=rngs) for i in range(n)])
    self.last_act = last_act

  def __call__(self, x):
    for i, layer in enumerate(self.layers):
      x = layer(x)
      if i < len(self.layers) - 1 or self.last_act:
        x = jax.nn.elu(x)
    return x


def add_encoders_and_core(module, model_cfg, encoder_sizes, dim: int, rngs: nnx.Rngs) -> None:
  """Gives ``module`` the three encoders (state ``[2 dim]``, offset and target ``[dim]``: ELU layers of
  ``encoder_sizes``) and the recurrent core over their concatenation: the part the Harvey model and the
  cvae system's sampler share (see :func:`encode_step`)."""
  enc = tuple(encoder_sizes)
  module.width = enc[-1]
  module.state_encoder = MLP((2 * dim, *enc), rngs=rngs)
  module.offset_encoder = MLP((dim, *enc), rngs=rngs)
  module.target_encoder = MLP((dim, *enc), rngs=rngs)
  module.core = RecurrentCore(
    model_cfg.cell,
    3 * module.width,
    model_cfg.hidden_size,
    model_cfg.num_layers,
    1,
    forget_bias=model_cfg.forget_bias,
    initial_state="zero",
    rngs=rngs,
  )


def encode_step(module, carry, state_BxS, offset_BxK, target_BxK, tta_B, z_BxE=0.0):
  """One frame through the encoders (the time-to-arrival embedding added to each, ``z_BxE`` to the offset
  and target encodings) and the core: ``(carry, h)``."""
  z_tta = tta_embedding(tta_B, module.width)
  h_state = module.state_encoder(state_BxS) + z_tta
  h_offset = module.offset_encoder(offset_BxK) + z_tta + z_BxE
  h_target = module.target_encoder(target_BxK) + z_tta + z_BxE
  return module.core.step(carry, jnp.concatenate([h_state, h_offset, h_target], -1))


class TransitionModel(nnx.Module):
  """Harvey-style recurrent transition model over flat local poses of ``dim`` (= 3J) numbers."""

  core: RecurrentCore  # with width and the three encoders: add_encoders_and_core

  def __init__(self, model_cfg, ib_cfg, dim: int, *, rngs: nnx.Rngs):
    self.dim = dim
    add_encoders_and_core(self, model_cfg, ib_cfg.encoder_sizes, dim, rngs)
    self.decoder = MLP((model_cfg.hidden_size, *ib_cfg.decoder_sizes, dim), last_act=False, zero_last=True, rngs=rngs)

  def initial_carry(self, batch: int):
    return self.core.initial_carry(jnp.zeros((batch, 1), jnp.float32))

  def step(self, carry, deviation_BxK, velocity_BxK, offset_BxK, target_BxK, tta_B, z_target_BxE):
    """One frame: ``(carry, the next frame's deviation from linear interpolation [B, K])``."""
    z = z_target_BxE * noise_strength(tta_B)[:, None]
    state = jnp.concatenate([DEVIATION_GAIN * deviation_BxK, VELOCITY_GAIN * velocity_BxK], -1)
    carry, h = encode_step(self, carry, state, OFFSET_GAIN * offset_BxK, target_BxK, tta_B, z)
    return carry, OUTPUT_SCALE * self.decoder(h)


def interpolation(last_BxK, target_BxK, s, context: int, length_B):
  """The linear interpolation's frame ``s`` of a window (last context frame at ``context - 1``, the target
  at ``context + length``); frames up to the last context frame are that frame."""
  alpha = jnp.clip((s - (context - 1)) / (length_B + 1.0), 0.0, 1.0)[:, None]
  return last_BxK + alpha * (target_BxK - last_BxK)


def rollout(model: TransitionModel, context_BxCxK, target_BxK, length_B, frames: int, z_target_BxE):
  """The ``frames`` frames after the context (``[B, frames, K]``); the target stands ``length_B`` frames
  after the last context frame, so frames ``length_B`` and later of a row are past its target (computed,
  meaningless). The context frames are fed in as they are, then the model's own frames."""
  b, c, _ = context_BxCxK.shape
  last, length = context_BxCxK[:, -1], length_B.astype(jnp.float32)
  fed = jnp.swapaxes(context_BxCxK, 0, 1)  # [C, B, K]: context frame s follows step s while s < C

  def body(carry, s):
    core, prev, prev2 = carry
    tta = (c - 1 + length + 1) - s  # the target is frame C + length
    deviation = prev - interpolation(last, target_BxK, s - 1, c, length)
    core, out = model.step(core, deviation, prev - prev2, target_BxK - prev, target_BxK, tta, z_target_BxE)
    frame = interpolation(last, target_BxK, s, c, length) + out
    nxt = jnp.where(s < c, fed[jnp.minimum(s, c - 1)], frame)
    return (core, nxt, prev), frame

  first = context_BxCxK[:, 0]
  steps = jnp.arange(1, c + frames)
  _, frames_TxBxK = jax.lax.scan(body, (model.initial_carry(b), first, first), steps)
  return jnp.swapaxes(frames_TxBxK[c - 1 :], 0, 1)


# ---------------------------------------------------------------- what both systems' losses share


def window_target(window_BxWxK, context: int, length_B):
  """Each row's target: frame ``context + length`` of its window ``[B, K]``."""
  return jnp.take_along_axis(window_BxWxK, (context + length_B)[:, None, None], axis=1)[:, 0]


def up_to_target(written_BxNxK, real_BxN1xK, length_B):
  """``(frames [B, N + 1, K], before [B, N + 1], up to [B, N + 1])``: the written frames before each row's
  target, the real ones from it on (the target itself, then frames masked out); the masks of the frames
  before the target and of those up to and including it."""
  idx, length = jnp.arange(real_BxN1xK.shape[1])[None], length_B[:, None]
  before = idx < length
  frames = jnp.where(before[..., None], jnp.concatenate([written_BxNxK, real_BxN1xK[:, -1:]], 1), real_BxN1xK)
  return frames, before.astype(jnp.float32), (idx <= length).astype(jnp.float32)


def balanced(err_BxT, mask_BxT, length_B, max_frames: int):
  """Each row's mean over its masked frames divided by ``length + 1``, then over the rows: interpolation's
  error grows about linearly with the length, so every length weighs alike (a plain mean over frames would
  weigh a 30-frame row some 36 times a 5-frame one, and a model would not learn short transitions)."""
  weight = 1.0 / (length_B + 1.0)
  rows = (err_BxT * mask_BxT).sum(1) / mask_BxT.sum(1)
  return (rows * weight).sum() / weight.sum() * (max_frames + 1) / 2


def transition_l1(written_BxNxK, real_BxNxK, length_B):
  """The validation loss: the pose L1 of the written frames before each row's target."""
  mask = (jnp.arange(written_BxNxK.shape[1])[None] < length_B[:, None]).astype(jnp.float32)
  return (jnp.abs(written_BxNxK - real_BxNxK).mean(-1) * mask).sum() / mask.sum()
