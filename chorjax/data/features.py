"""The fitted feature pipeline: data-space joint positions <-> normalized model features.

encode: rotate to y-up -> scale units -> representation (absolute / bone-relative /
root-relative) -> flatten ``[T, J*3]`` -> normalize with training-split statistics.
decode is the exact inverse, so a sample comes back in the data's own units and axes.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from chorjax.data import transforms
from chorjax.data.motion import Skeleton

REPRESENTATIONS = ("absolute", "bone_relative", "root_relative")


@dataclasses.dataclass(frozen=True, eq=False)
class Features:
  """Everything needed to map positions to model features and back.

  Attributes:
    skeleton: the joint tree.
    representation: one of ``REPRESENTATIONS``.
    up_axis: the signed up axis of the data space (rotated to y-up inside).
    scale: multiplies lengths before the representation (e.g. to metres).
    mean, std: ``[D]`` normalization statistics of the training split (ddof=1).
  """

  skeleton: Skeleton
  representation: str
  up_axis: str
  scale: float
  mean: np.ndarray
  std: np.ndarray

  @property
  def dim(self) -> int:
    return 3 * self.skeleton.num_joints

  def canonical(self, pos_TxJx3):
    """Data space -> y-up, scaled positions (before the representation)."""
    return transforms.scale_units(transforms.to_y_up(pos_TxJx3, self.up_axis), self.scale)

  def uncanonical(self, pos_TxJx3):
    return transforms.rotate(
      transforms.scale_units(pos_TxJx3, 1.0 / self.scale), transforms.up_axis_matrix(self.up_axis).T
    )

  def represent(self, canon_TxJx3):
    """Canonical positions -> un-normalized flat features ``[T, D]``."""
    rep = _represent(canon_TxJx3, self.skeleton, self.representation)
    return rep.reshape(rep.shape[:-2] + (self.dim,))

  def encode(self, pos_TxJx3):
    """Data-space positions ``[..., T, J, 3]`` -> normalized features ``[..., T, D]``."""
    return transforms.normalize(self.represent(self.canonical(pos_TxJx3)), self.mean, self.std)

  def decode(self, z_TxD):
    """Normalized features ``[..., T, D]`` -> data-space positions ``[..., T, J, 3]``."""
    rep = transforms.denormalize(z_TxD, self.mean, self.std)
    rep = rep.reshape(rep.shape[:-1] + (self.skeleton.num_joints, 3))
    return self.uncanonical(_unrepresent(rep, self.skeleton, self.representation))

  def to_dict(self) -> dict:
    return {
      "skeleton": self.skeleton.to_dict(),
      "representation": self.representation,
      "up_axis": self.up_axis,
      "scale": self.scale,
      "mean": np.asarray(self.mean).tolist(),
      "std": np.asarray(self.std).tolist(),
    }

  @classmethod
  def from_dict(cls, d: dict) -> Features:
    return cls(
      Skeleton.from_dict(d["skeleton"]),
      d["representation"],
      d["up_axis"],
      float(d["scale"]),
      np.asarray(d["mean"], np.float32),
      np.asarray(d["std"], np.float32),
    )


def _represent(pos, skeleton: Skeleton, representation: str):
  if representation == "absolute":
    return jnp.asarray(pos)
  if representation == "bone_relative":
    return transforms.to_bone_relative(pos, skeleton.parents)
  if representation == "root_relative":
    return transforms.to_root_relative(pos, skeleton.root)
  raise ValueError(f"unknown representation {representation!r}; one of {REPRESENTATIONS}")


def _unrepresent(rep, skeleton: Skeleton, representation: str):
  if representation == "absolute":
    return rep
  if representation == "bone_relative":
    return transforms.from_bone_relative(rep, skeleton.parents)
  if representation == "root_relative":
    return transforms.from_root_relative(rep, skeleton.root)
  raise ValueError(f"unknown representation {representation!r}; one of {REPRESENTATIONS}")
