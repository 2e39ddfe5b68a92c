"""Autoregressive generation: one jit-compiled ``lax.scan`` over frames, K dancers as a batch.

The model's own ``step`` (the same cell code that training scans) consumes the previous frame and
the head draws the next one. Priming runs the model teacher-forced over a real phrase and continues
from its state: chor-rnn's collaboration mode. Results go back to data space through the exact
inverse of the feature pipeline.
"""

from __future__ import annotations

import functools
from typing import Optional

import jax
import jax.numpy as jnp
import numpy as np
from flax import nnx

from chorjax.errors import UserError


@functools.partial(jax.jit, static_argnames=("graphdef", "num_frames", "greedy"))
def generate(graphdef, params, weights_BxM, key, *, num_frames: int, prime_BxPxD=None,
             pi_temperature=1.0, sigma_temperature=1.0, greedy: bool = False):
  """Generates ``num_frames`` normalized frames per row of ``weights_BxM``.

  Args:
    graphdef: the model's static graph (``nnx.split``).
    params: the model parameters (an argument, not a closure, so the program stays small).
    weights_BxM: motion-id weights (one-hot or a blend) per dancer.
    key: PRNG key; the same key gives the same dance.
    num_frames: frames to generate after the prime.
    prime_BxPxD: optional real phrase (normalized); generation continues after its last frame.
      Without it, generation starts from the zero frame (the mean pose) and the id's state.
    pi_temperature, sigma_temperature, greedy: MDN sampling controls (see ``heads.mdn_sample``).

  Returns:
    ``[B, num_frames, D]`` normalized frames.
  """
  model = nnx.merge(graphdef, params)
  carry = model.initial_carry(weights_BxM)
  if prime_BxPxD is not None:
    _, carry = model.run(prime_BxPxD[:, :-1], carry)  # teacher-forced over the phrase
    x0 = prime_BxPxD[:, -1]
  else:
    x0 = jnp.zeros((weights_BxM.shape[0], model.dim), jnp.float32)

  def body(c, k):
    carry, x = c
    carry, raw = model.step(carry, x)
    x = model.sample(raw, k, pi_temperature, sigma_temperature, greedy)
    return (carry, x), x

  _, xs_NxBxD = jax.lax.scan(body, (carry, x0), jax.random.split(key, num_frames))
  return jnp.swapaxes(xs_NxBxD, 0, 1)


def prime_state(graphdef, params, weights_BxM, prime_BxPxD):
  """The carry after teacher-forcing the whole phrase (for tests and inspection)."""
  model = nnx.merge(graphdef, params)
  return model.run(prime_BxPxD, model.initial_carry(weights_BxM))[1]


def parse_mix(text: str, num_motions: int) -> np.ndarray:
  """``'4:0.5,5:0.5'`` -> a weight vector over the motions (normalized to sum 1)."""
  w = np.zeros(num_motions, np.float32)
  for part in text.split(","):
    try:
      i, v = part.split(":")
      i, v = int(i), float(v)
    except ValueError:
      raise UserError(f"--mix {text!r}: expected ID:WEIGHT,ID:WEIGHT (e.g. 4:0.5,5:0.5)") from None
    if not 0 <= i < num_motions:
      raise UserError(f"--mix {text!r}: motion id {i} out of range (0..{num_motions - 1})")
    w[i] += v
  if w.sum() <= 0:
    raise UserError(f"--mix {text!r}: weights must sum to a positive number")
  return w / w.sum()


def motion_weight_vector(num_motions: int, motion: Optional[int] = None, mix: Optional[str] = None,
                         source: str = "--motion"):
  """One-hot weights of ``motion`` (default 0), or the blend ``mix``; ``source`` names the setting in errors."""
  if mix:
    return parse_mix(mix, num_motions)
  motion = 0 if motion is None else motion
  if not 0 <= motion < num_motions:
    raise UserError(f"{source} {motion}: out of range (0..{num_motions - 1})")
  return np.eye(num_motions, dtype=np.float32)[motion]


def sampling_settings(meta: dict, pi_temperature=None, sigma_temperature=None, greedy=None) -> dict:
  """Sampling controls: the ones given, else the run's ``[sample]`` config (saved in ``meta``)."""
  run = meta["config"]["sample"]
  return {"pi_temperature": run["pi_temperature"] if pi_temperature is None else pi_temperature,
          "sigma_temperature": run["sigma_temperature"] if sigma_temperature is None else sigma_temperature,
          "greedy": bool(run["greedy"] if greedy is None else greedy)}


def load_run(workdir, which: str | int = "latest"):
  """``(graphdef, params, meta)`` of a run's checkpoint (``latest``, ``best`` or a step number)."""
  from pathlib import Path
  from chorjax import checkpoint as ckpt
  from chorjax.config import config_from_dict
  from chorjax.train import init_state

  workdir = Path(workdir)
  if not workdir.is_dir():
    raise UserError(f"{workdir}: no such run directory")
  manager = ckpt.open_run(workdir)
  try:
    step = ckpt.resolve_step(manager, which, workdir)
    meta = ckpt.step_meta(manager, step)
    cfg = config_from_dict(meta["config"])
    dim = 3 * len(meta["features"]["skeleton"]["joint_names"])
    graphdef, template, _, _ = init_state(cfg, dim, len(meta["id_map"]))
    state = ckpt.restore(manager, step, template)
  finally:
    manager.close()
  return graphdef, state["params"], meta


def read_prime(spec: str, features, data_cfg) -> np.ndarray:
  """``FILE[:START:LEN]`` -> normalized frames ``[P, D]`` of a real phrase, read as training read its
  takes (``data_cfg`` is the run's DataConfig: joints mapped, rotated to its up axis)."""
  from pathlib import Path
  from chorjax.data.dataset import conform, read_takes

  parts = spec.rsplit(":", 2)
  if len(parts) == 3 and parts[1].isdigit() and parts[2].isdigit():
    path, start, length = Path(parts[0]), int(parts[1]), int(parts[2])
  else:
    path, start, length = Path(spec), 0, None
  motion = conform(read_takes([str(path)], data_cfg)[:1], data_cfg)[0]
  if motion.skeleton.num_joints != features.skeleton.num_joints:
    raise UserError(f"{path}: {motion.skeleton.num_joints} joints; the model was trained on "
                    f"{features.skeleton.num_joints}")
  end = motion.num_frames if length is None else start + length
  if start >= motion.num_frames or end > motion.num_frames or end - start < 2:
    raise UserError(f"--prime {spec}: frames {start}..{end} are not inside the take's {motion.num_frames} frames "
                    "(need at least 2)")
  return np.asarray(features.encode(motion.positions[start:end]), np.float32)
