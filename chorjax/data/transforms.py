"""Pure transforms on joint positions, each with its exact inverse where one exists.

Every function here takes and returns arrays (``jax.numpy`` or NumPy), has no side effects, and
works under ``jax.jit`` and ``jax.vmap``. Positions are ``[..., T, J, 3]``; features are
``[..., T, D]`` with ``D = 3 * J``.

Normalization statistics are the one exception to "jax.numpy": they are accumulated on the host
in float64 (Chan et al.'s parallel merge of count/mean/M2), once per dataset.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np

# ---------------------------------------------------------------- normalization statistics


@dataclasses.dataclass(frozen=True)
class Stats:
  """Running statistics of feature columns: count, mean and sum of squared deviations (M2)."""

  count: int
  mean: np.ndarray
  m2: np.ndarray

  @classmethod
  def of(cls, x_TxD) -> Stats:
    x = np.asarray(x_TxD, dtype=np.float64)
    mean = x.mean(axis=0)
    return cls(x.shape[0], mean, ((x - mean) ** 2).sum(axis=0))

  def merge(self, other: Stats) -> Stats:
    """Chan et al.'s pairwise update: exact for any split of the rows."""
    n = self.count + other.count
    delta = other.mean - self.mean
    mean = self.mean + delta * (other.count / n)
    m2 = self.m2 + other.m2 + delta**2 * (self.count * other.count / n)
    return Stats(n, mean, m2)

  def std(self, ddof: int = 1, floor: float = 1e-8) -> np.ndarray:
    return np.sqrt(np.maximum(self.m2 / max(self.count - ddof, 1), floor**2))


def merged_stats(arrays: Sequence[np.ndarray]) -> Stats:
  """Merges per-file statistics of ``[T_i, D]`` arrays into one."""
  stats = [Stats.of(a) for a in arrays]
  out = stats[0]
  for s in stats[1:]:
    out = out.merge(s)
  return out


def normalize(x, mean, std):
  return (x - mean) / std


def denormalize(z, mean, std):
  return z * std + mean


# ---------------------------------------------------------------- skeleton-relative coordinates


def to_bone_relative(pos_TxJx3, parents: Sequence[int]):
  """Root absolute; every other joint as the offset from its parent along the bone."""
  parent_of = np.asarray(parents)
  root = np.flatnonzero(parent_of < 0)
  parent_pos = pos_TxJx3[..., np.where(parent_of < 0, root[0], parent_of), :]
  is_root = (parent_of < 0)[:, None]
  return jnp.where(is_root, pos_TxJx3, pos_TxJx3 - parent_pos)


def ancestor_matrix(parents: Sequence[int]) -> np.ndarray:
  """``A[j, k] = 1`` if joint k is j or one of its ancestors: absolute = A @ bone-relative."""
  j = len(parents)
  a = np.zeros((j, j), np.float32)
  for joint in range(j):
    k = joint
    while k >= 0:
      a[joint, k] = 1.0
      k = parents[k]
  return a


def from_bone_relative(rel_TxJx3, parents: Sequence[int]):
  """Inverse of ``to_bone_relative``: walks the tree by summing offsets along each joint's path."""
  return jnp.einsum("jk,...kc->...jc", ancestor_matrix(parents), rel_TxJx3)


def to_root_relative(pos_TxJx3, root: int):
  """Root absolute; every other joint as the offset from the root."""
  is_root = (np.arange(pos_TxJx3.shape[-2]) == root)[:, None]
  return jnp.where(is_root, pos_TxJx3, pos_TxJx3 - pos_TxJx3[..., root : root + 1, :])


def from_root_relative(rel_TxJx3, root: int):
  is_root = (np.arange(rel_TxJx3.shape[-2]) == root)[:, None]
  return jnp.where(is_root, rel_TxJx3, rel_TxJx3 + rel_TxJx3[..., root : root + 1, :])


# ---------------------------------------------------------------- axes, units, time


def up_axis_matrix(up_axis: str) -> np.ndarray:
  """The rotation taking coordinates whose up axis is ``up_axis`` to y-up.

  A proper rotation (det +1), never a reflection, so left stays left:
  ``-y`` (y down) turns 180 degrees about x; ``z`` turns -90 degrees about x; and so on.
  """
  table = {
    "y": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
    "-y": [[1, 0, 0], [0, -1, 0], [0, 0, -1]],
    "z": [[1, 0, 0], [0, 0, 1], [0, -1, 0]],
    "-z": [[1, 0, 0], [0, 0, -1], [0, 1, 0]],
    "x": [[0, 1, 0], [1, 0, 0], [0, 0, -1]],
    "-x": [[0, -1, 0], [1, 0, 0], [0, 0, 1]],
  }
  if up_axis not in table:
    raise ValueError(f"unknown up axis {up_axis!r}; one of {sorted(table)}")
  return np.asarray(table[up_axis], np.float32)


def to_y_up(pos_Tx_x3, up_axis: str):
  """Positions whose up axis is ``up_axis`` -> the same positions with y up (a rotation)."""
  return rotate(pos_Tx_x3, up_axis_matrix(up_axis))


def rotate(pos_Tx_x3, matrix_3x3):
  """Applies a 3x3 matrix to every point. With ``matrix.T`` it undoes a rotation."""
  return jnp.einsum("ij,...j->...i", matrix_3x3, pos_Tx_x3)


def scale_units(pos, factor: float):
  return pos * factor


def resample(pos_TxJx3, fps_in: float, fps_out: float):
  """Linear interpolation in time to another frame rate (first frame kept; no exact inverse)."""
  t_in = pos_TxJx3.shape[-3]
  t_out = int(np.floor((t_in - 1) * fps_out / fps_in)) + 1
  src = np.arange(t_out) * (fps_in / fps_out)
  lo = np.minimum(np.floor(src).astype(np.int32), t_in - 1)
  hi = np.minimum(lo + 1, t_in - 1)
  w = (src - lo).astype(np.float32)[:, None, None]
  return pos_TxJx3[..., lo, :, :] * (1 - w) + pos_TxJx3[..., hi, :, :] * w


# ---------------------------------------------------------------- augmentations


def reverse_time(x, time_axis: int = 0):
  """The motion played backwards (its own inverse)."""
  return jnp.flip(x, axis=time_axis)


def mirror(pos_TxJx3, twins: Sequence[int], lateral_axis: int = 0):
  """Left/right mirror: swap twin joints and negate the lateral axis (its own inverse)."""
  sign = np.ones(3, np.float32)
  sign[lateral_axis] = -1.0
  return pos_TxJx3[..., np.asarray(twins), :] * sign
