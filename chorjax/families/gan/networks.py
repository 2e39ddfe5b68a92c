"""The LSTM-GAN family (the generative-dance tutorials' LSTM-GAN): a generator turns a noise vector into a
whole pose sequence, a critic tells real sequences from generated ones.

Generator: noise ``z [B, Z]`` -> dense ReLU layers -> the vector repeated once per frame (beside
``gan.frame_noise`` channels of fresh noise per frame, where asked: C-RNN-GAN's per-frame input, so the
recurrent state keeps being driven) -> stacked recurrent layers -> a dense layer per frame to the pose
features. The recurrent layers unroll to any
number of frames, so a sequence of any length can be drawn (quality past the training length is measured
in ``experiments/families``). Critic: stacked recurrent layers over the sequence -> the last time step ->
dense ReLU layers -> one logit (a probability through a sigmoid for the ``bce`` loss; a Wasserstein
score for ``wgan-gp``).

Both use the cells of :mod:`chorjax.models.cells` (their fused layers support the second derivative the
gradient penalty needs; ``tests/test_gan.py`` checks it against a plain scan). :class:`Projection` makes
the generator's bone directions unit vectors (the positions-only stand-in for normalized quaternions);
:class:`Kinematics` takes unit quaternions through forward kinematics, as the tutorial does.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools

import jax
import jax.numpy as jnp
import numpy as np
from flax import nnx

from chorjax.families.family import frame_io
from chorjax.models.rnn import RecurrentCore


def _dense_stack(sizes, *, rngs: nnx.Rngs) -> nnx.List:
  return nnx.List([nnx.Linear(a, b, rngs=rngs) for a, b in itertools.pairwise(sizes)])


class Generator(nnx.Module):
  """``generator(z_BxZ, num_frames)`` -> normalized features ``[B, num_frames, D]``."""

  def __init__(self, gan, dim: int, *, rngs: nnx.Rngs):
    sizes = (gan.latent_size, *gan.generator_dense)
    self.latent_size, self.frame_noise = gan.latent_size, gan.frame_noise
    self.dense = _dense_stack(sizes, rngs=rngs)
    self.core = RecurrentCore(
      gan.cell,
      sizes[-1] + gan.frame_noise,
      gan.generator_size,
      gan.generator_layers,
      1,
      initial_state="zero",
      rngs=rngs,
    )
    self.out = nnx.Linear(gan.generator_size, dim, rngs=rngs)

  def __call__(self, z_BxZ, num_frames: int, noise_BxTxF=None):
    """``noise_BxTxF``: fresh noise for every frame, beside the repeated vector (``gan.frame_noise``
    channels; needed when it is > 0)."""
    h = z_BxZ
    for layer in self.dense:
      h = nnx.relu(layer(h))
    x_BxTxE = jnp.broadcast_to(h[:, None], (h.shape[0], num_frames, h.shape[-1]))
    if self.frame_noise:
      assert noise_BxTxF is not None, "gan.frame_noise > 0: the generator needs per-frame noise"
      x_BxTxE = jnp.concatenate([x_BxTxE, noise_BxTxF], -1)
    h_BxTxH, _ = self.core(x_BxTxE, self.core.initial_carry(jnp.zeros((h.shape[0], 1), h.dtype)))
    return self.out(h_BxTxH)


class Critic(nnx.Module):
  """``critic(x_BxTxD)`` -> one logit per sequence ``[B]``."""

  def __init__(self, gan, dim: int, *, rngs: nnx.Rngs):
    self.core = RecurrentCore(gan.cell, dim, gan.critic_size, gan.critic_layers, 1, initial_state="zero", rngs=rngs)
    sizes = (gan.critic_size, *gan.critic_dense)
    self.dense = _dense_stack(sizes, rngs=rngs)
    self.out = nnx.Linear(sizes[-1], 1, rngs=rngs)

  def __call__(self, x_BxTxD):
    h_BxTxH, _ = self.core(x_BxTxD, self.core.initial_carry(jnp.zeros((x_BxTxD.shape[0], 1), x_BxTxD.dtype)))
    h = h_BxTxH[:, -1]
    for layer in self.dense:
      h = nnx.relu(layer(h))
    return self.out(h)[:, 0]


class GanModel(nnx.Module):
  """The generator and the critic, one parameter tree ``{generator, critic}`` (one checkpoint).
  ``pose`` (``gan.pose``): what the generator writes, turned into the features the critic sees by
  :func:`pose_layer` (``directions``: unit bone directions; ``rotations``: unit quaternions through forward
  kinematics, the generator writing ``4 + 4 J`` numbers; ``features``: the features themselves)."""

  def __init__(self, gan, dim: int, *, rngs: nnx.Rngs):
    self.dim, self.latent_size, self.pose = dim, gan.latent_size, gan.pose
    joints = (dim - 3) // 3  # the directions representation: 3 + 3 J features
    self.generator = Generator(gan, 4 + 4 * joints if gan.pose == "rotations" else dim, rngs=rngs)
    self.critic = Critic(gan, dim, rngs=rngs)


def _as_tuple(a) -> tuple:
  return tuple(float(v) for v in np.asarray(a).ravel())


@dataclasses.dataclass(frozen=True)
class Projection:
  """Makes the bone directions of generated ``directions`` features unit vectors (in normalized feature
  space: denormalized, each bone's triple divided by its length, normalized again). Hashable, so it can
  be part of a static jit argument.

  Attributes:
    starts: the first feature of every bone-direction triple.
    mean, std: the ``[D]`` normalization statistics, as tuples.
  """

  starts: tuple
  mean: tuple
  std: tuple

  @classmethod
  def of(cls, features) -> Projection:
    """For a run's ``Features`` of the ``directions`` representation (every joint but the root, whose
    triple holds its height)."""
    root = features.skeleton.root
    starts = tuple(3 + 3 * j for j in range(features.skeleton.num_joints) if j != root)
    return cls(starts, _as_tuple(features.mean), _as_tuple(features.std))

  def __call__(self, x_xD):
    mean, std = jnp.asarray(self.mean, x_xD.dtype), jnp.asarray(self.std, x_xD.dtype)
    idx = jnp.asarray(self.starts)[:, None] + jnp.arange(3)  # [bones, 3]
    raw = x_xD * std + mean
    dirs = raw[..., idx]
    unit = dirs / jnp.sqrt(jnp.sum(dirs * dirs, -1, keepdims=True) + 1e-8)
    return (raw.at[..., idx].set(unit) - mean) / std


def quaternion_product(a, b):
  """Hamilton product of ``[..., 4]`` quaternions ``(w, x, y, z)``."""
  aw, av, bw, bv = a[..., :1], a[..., 1:], b[..., :1], b[..., 1:]
  return jnp.concatenate([aw * bw - jnp.sum(av * bv, -1, keepdims=True), aw * bv + bw * av + jnp.cross(av, bv)], -1)


def quaternion_rotate(q, v):
  """``v [..., 3]`` rotated by the unit quaternions ``q [..., 4]``."""
  w, u = q[..., :1], q[..., 1:]
  t = 2.0 * jnp.cross(u, v)
  return v + w * t + jnp.cross(u, t)


@dataclasses.dataclass(frozen=True)
class Kinematics:
  """Forward kinematics for ``gan.pose = "rotations"``: the generator writes the root's step (3, normalized
  as the features), its height (1, normalized) and per joint a local rotation as a quaternion (4 x J,
  made unit length); each joint's rotation is its parent's times its own, and its bone points along its
  rest direction (the takes' mean) turned by it. Out come the ``directions`` features the critic sees
  (unit bone directions; the lengths are the takes' means when decoded). Hashable (a static jit argument).

  Attributes:
    parents: the skeleton's parent of every joint (-1: the root); order: joints parents first.
    rest: ``[J x 3]`` every bone's rest direction, flattened; mean, std: the features' statistics.
  """

  parents: tuple
  order: tuple
  rest: tuple
  mean: tuple
  std: tuple

  @classmethod
  def of(cls, features) -> Kinematics:
    """For a run's ``Features`` of the ``directions`` representation."""
    sk, mean = features.skeleton, np.asarray(features.mean, np.float64)
    rest = mean[3:].reshape(sk.num_joints, 3)
    norm = np.linalg.norm(rest, axis=-1, keepdims=True)
    rest = np.where(norm > 1e-6, rest / np.maximum(norm, 1e-6), [0.0, 1.0, 0.0])
    return cls(
      tuple(sk.parents), tuple(sk.topological_order), _as_tuple(rest), _as_tuple(mean), _as_tuple(features.std)
    )

  def __call__(self, out_xO):
    mean, std = jnp.asarray(self.mean, out_xO.dtype), jnp.asarray(self.std, out_xO.dtype)
    num = len(self.parents)
    q = out_xO[..., 4:].reshape(out_xO.shape[:-1] + (num, 4))
    q = q / jnp.sqrt(jnp.sum(q * q, -1, keepdims=True) + 1e-8)
    rest = jnp.asarray(self.rest, out_xO.dtype).reshape(num, 3)
    glob: dict[int, jnp.ndarray] = {}
    dirs: dict[int, jnp.ndarray] = {}
    root = self.parents.index(-1)
    for j in self.order:
      p = self.parents[j]
      glob[j] = q[..., j, :] if p < 0 else quaternion_product(glob[p], q[..., j, :])
      dirs[j] = quaternion_rotate(glob[j], rest[j])
    height = out_xO[..., 3:4] * std[3 + 3 * root + 1] + mean[3 + 3 * root + 1]
    zero = jnp.zeros_like(height)
    dirs[root] = jnp.concatenate([zero, height, zero], -1)
    raw = jnp.concatenate([out_xO[..., :3] * std[:3] + mean[:3], *(dirs[j] for j in range(num))], -1)
    return (raw - mean) / std


def pose_layer(features, pose: str):
  """What turns the generator's output into the features the critic sees, for ``gan.pose``: a
  :class:`Projection`, :class:`Kinematics`, or None (``features``: the output is the features)."""
  return {"directions": Projection, "rotations": Kinematics}[pose].of(features) if pose != "features" else None


def generator_noise(generator: Generator, key, num: int, frames: int):
  """``(z [num, Z], frame noise [num, frames, F])``: the standard-normal noise a draw with ``key`` feeds the
  generator (:func:`fake_sequences`; :func:`frame_numbers` hands the same numbers to an exported graph)."""
  k_z, k_frames = jax.random.split(key)
  z = jax.random.normal(k_z, (num, generator.latent_size))
  return z, jax.random.normal(k_frames, (num, frames, generator.frame_noise))


def fake_sequences(generator: Generator, key, num: int, frames: int, projection=None):
  """``num`` generated sequences of ``frames`` frames ``[num, frames, D]`` from standard-normal noise, through
  ``projection`` (:func:`pose_layer`) where given."""
  z, noise = generator_noise(generator, key, num, frames)
  x = generator(z, frames, noise)
  return x if projection is None else projection(x)


@functools.partial(jax.jit, static_argnames=("graphdef", "num", "num_frames", "projection"))
def generate_sequences(graphdef, params, key, *, num: int, num_frames: int, projection=None, bounds=None):
  """Sampling: ``[num, num_frames, D]`` normalized frames from a trained :class:`GanModel` (``projection``:
  its :func:`pose_layer`); ``bounds``: each feature clipped to ``(low, high)`` (``sample.clamp``; a clipped
  bone direction is renormalized when decoded)."""
  model = nnx.merge(graphdef, params)
  x = fake_sequences(model.generator, key, num, num_frames, projection)
  return x if bounds is None else jnp.clip(x, *bounds)


def frame_numbers(graphdef, params, key, frames: int, batch: int):
  """``(gumbel [T, B, 1], normal [T, B, Z + F])``: the numbers :func:`fake_sequences` draws with ``key``, frame
  by frame as :func:`frame_program` takes them: every frame's normal row holds the noise vector (read on a
  dancer's first frame) and that frame's ``gan.frame_noise`` channels; no component to pick."""
  gen = nnx.merge(graphdef, params).generator
  z, noise = generator_noise(gen, key, batch, frames)
  normal = jnp.concatenate([jnp.broadcast_to(z[:, None], (batch, frames, gen.latent_size)), noise], -1)
  return jnp.zeros((frames, batch, 1), jnp.float32), jnp.swapaxes(normal, 0, 1)


def frame_program(graphdef, params, features, draw, batch: int, num_motions: int):
  """The generator one frame a call (``Family.frame_program``): on a dancer's first frame (``start``) the
  noise vector (the first ``Z`` of ``normal``) goes through the dense layers and the recurrent state starts
  at zero; each frame its ``gan.frame_noise`` channels (the rest of ``normal``) join that vector, one
  recurrent step and the output layer give the frame, through the pose layer and the training range
  (``sample.clamp``) as :func:`generate_sequences` does. ``weights`` and ``gumbel`` are not read."""
  model = nnx.merge(graphdef, params)
  gen = model.generator
  projection = pose_layer(features, model.pose)
  bounds = draw.bounds
  z_size, f_size = gen.latent_size, gen.frame_noise

  def fresh(normal):
    h = normal[:, :z_size]
    for layer in gen.dense:
      h = nnx.relu(layer(h))
    return gen.core.initial_carry(jnp.zeros((batch, 1), h.dtype)), h

  def program(weights, start, gumbel, normal, *leaves):
    del weights, gumbel
    restart = start > 0.5
    f_carry, f_h = fresh(normal)
    carry, h = jax.tree.unflatten(treedef, leaves)
    pick = lambda f, s: jnp.where(restart[:, None], f, s)
    carry, h = jax.tree.map(pick, f_carry, carry), pick(f_h, h)
    x_in = jnp.concatenate([h, normal[:, z_size : z_size + f_size]], -1) if f_size else h
    carry, y = gen.core.step(carry, x_in)
    x = gen.out(y)
    x = x if projection is None else projection(x[:, None])[:, 0]
    x = x if bounds is None else jnp.clip(x, bounds.low, bounds.high)
    return (x, *jax.tree.leaves((carry, h)))

  template = jax.eval_shape(fresh, jax.ShapeDtypeStruct((batch, z_size + f_size), jnp.float32))
  treedef, args, inputs, outputs = frame_io(template, ("carry", "vector"), batch, num_motions, 1, z_size + f_size)
  return program, args, inputs, outputs
