"""Motion-id conditioning: which choreography the model dances, as ids or as a blend of ids.

The model takes ``motion`` as integer ids ``[B]`` (one take each) or as weights ``[B, M]`` over the
dataset's ``M`` motions (a blend such as ``4:0.5,5:0.5``); :func:`as_weights` turns either into the
weights its initial-state layer reads.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from chorjax.errors import UserError


def as_weights(motion, num_motions: int):
  """Motion-id weights ``[B, M]`` from ids ``[B]`` (one-hot) or weights ``[B, M]`` (unchanged)."""
  motion = jnp.asarray(motion)
  if motion.ndim == 1 and jnp.issubdtype(motion.dtype, jnp.integer):
    return jax.nn.one_hot(motion, num_motions, dtype=jnp.float32)
  if motion.ndim != 2 or motion.shape[-1] != num_motions:
    raise ValueError(f"motion: expected ids [B] or weights [B, {num_motions}], got shape {motion.shape}")
  return motion


MAX_MIX_CHARS = 10_000  # a mix names at most a few thousand takes; longer text is refused unread


def parse_mix(text: str, num_motions: int) -> np.ndarray:
  """``'4:0.5,5:0.5'`` -> a weight vector over the motions; weights finite and >= 0, normalized to sum 1
  (so ``4:1,5:1`` is an even blend, and ``0:1e308,1:1e308`` too: no overflow to NaN)."""
  if len(text) > MAX_MIX_CHARS:
    raise UserError(f"--mix: {len(text)} characters; at most {MAX_MIX_CHARS}")
  w = np.zeros(num_motions, np.float64)
  parts = []
  for part in text.split(","):
    try:
      i_text, v_text = part.split(":")
      i, v = int(i_text), float(v_text)
    except ValueError:
      raise UserError(f"--mix {text[:80]!r}: expected ID:WEIGHT,ID:WEIGHT (e.g. 4:0.5,5:0.5)") from None
    if not 0 <= i < num_motions:
      raise UserError(f"--mix {text[:80]!r}: motion id {i} out of range (0..{num_motions - 1})")
    if not (np.isfinite(v) and v >= 0):
      raise UserError(f"--mix {text[:80]!r}: weight {v_text} must be a finite number >= 0")
    parts.append((i, v))
  top = max(v for _, v in parts)
  if top <= 0:
    raise UserError(f"--mix {text[:80]!r}: weights must sum to a positive number")
  for i, v in parts:  # divided by the largest first: huge weights cannot overflow the sum
    w[i] += v / top
  return (w / w.sum()).astype(np.float32)


def motion_weight_vector(
  num_motions: int, motion: int | None = None, mix: str | None = None, source: str = "--motion"
) -> np.ndarray:
  """One-hot weights ``[M]`` of ``motion`` (default 0), or the blend ``mix``; ``source`` names the
  setting in errors."""
  if mix:
    return parse_mix(mix, num_motions)
  motion = 0 if motion is None else motion
  if not 0 <= motion < num_motions:
    raise UserError(f"{source} {motion}: out of range (0..{num_motions - 1})")
  return np.eye(num_motions, dtype=np.float32)[motion]
