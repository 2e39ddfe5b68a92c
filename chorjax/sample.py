"""Autoregressive generation: one jit-compiled ``lax.scan`` over frames, K dancers as a batch.

The model's own ``step`` (the same cell code that training scans) consumes the previous frame and
the head draws the next one. Priming runs the model teacher-forced over a real phrase and continues
from its state: chor-rnn's collaboration mode. Results go back to data space through the exact
inverse of the feature pipeline.
"""

from __future__ import annotations

import functools
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from flax import nnx

from chorjax.data.dataset import conform, read_takes
from chorjax.errors import UserError


@functools.partial(jax.jit, static_argnames=("graphdef", "num_frames", "greedy"))
def generate(
  graphdef,
  params,
  motion,
  key,
  *,
  num_frames: int,
  prime_BxPxD=None,
  pi_temperature=1.0,
  sigma_temperature=1.0,
  greedy: bool = False,
):
  """Generates ``num_frames`` normalized frames per dancer.

  Args:
    graphdef: the model's static graph (``nnx.split``).
    params: the model parameters (an argument, not a closure, so the program stays small).
    motion: per dancer, what conditions it: motion ids ``[B]`` or weights ``[B, M]`` (a blend).
    key: PRNG key; the same key gives the same dance.
    num_frames: frames to generate after the prime.
    prime_BxPxD: optional real phrase (normalized); generation continues after its last frame.
      Without it, generation starts from the zero frame (the mean pose) and the id's state.
    pi_temperature, sigma_temperature, greedy: MDN sampling controls (see ``heads.mdn_sample``).

  Returns:
    ``[B, num_frames, D]`` normalized frames.
  """
  model = nnx.merge(graphdef, params)
  carry = model.initial_carry(motion)
  if prime_BxPxD is not None:
    _, carry = model.teacher_force(prime_BxPxD[:, :-1], carry)
    x0 = prime_BxPxD[:, -1]
  else:
    x0 = jnp.zeros((jnp.shape(motion)[0], model.dim), jnp.float32)

  def body(c, k):
    carry, x = c
    carry, out = model.step(carry, x)
    x = model.sample(out, k, pi_temperature, sigma_temperature, greedy)
    return (carry, x), x

  _, xs_NxBxD = jax.lax.scan(body, (carry, x0), jax.random.split(key, num_frames))
  return jnp.swapaxes(xs_NxBxD, 0, 1)


def read_prime(spec: str, features, data_cfg) -> np.ndarray:
  """``FILE[:START:LEN]`` -> normalized frames ``[P, D]`` of a real phrase, read as training read its
  takes (``data_cfg`` is the run's DataConfig: joints mapped, rotated to its up axis)."""
  parts = spec.rsplit(":", 2)
  if len(parts) == 3 and parts[1].isdigit() and parts[2].isdigit():
    path, start, length = Path(parts[0]), int(parts[1]), int(parts[2])
  else:
    path, start, length = Path(spec), 0, None
  motion = conform(read_takes([str(path)], data_cfg)[:1], data_cfg)[0]
  if motion.skeleton.num_joints != features.skeleton.num_joints:
    raise UserError(
      f"{path}: {motion.skeleton.num_joints} joints; the model was trained on {features.skeleton.num_joints}"
    )
  end = motion.num_frames if length is None else start + length
  if start >= motion.num_frames or end > motion.num_frames or end - start < 2:
    raise UserError(
      f"--prime {spec}: frames {start}..{end} are not inside the take's {motion.num_frames} frames (need at least 2)"
    )
  return np.asarray(features.encode(motion.positions[start:end]), np.float32)
