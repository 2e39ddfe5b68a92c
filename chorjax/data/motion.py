"""The two records every reader produces and every writer consumes: ``Skeleton`` and ``Motion``."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np


@dataclasses.dataclass(frozen=True)
class Skeleton:
  """A joint tree.

  Attributes:
    name: a short name (e.g. ``mpii16``).
    joint_names: one name per joint.
    parents: parent index per joint, -1 for a root (one root for a skeleton; marker sets: all -1).
    twins: the left/right twin of each joint (itself for joints on the midline); used by mirroring.
    end_joints: joints plotted as trajectories (feet, head top, hands).
    feet: the foot joints (for foot-contact metrics).
  """

  name: str
  joint_names: tuple[str, ...]
  parents: tuple[int, ...]
  twins: tuple[int, ...]
  end_joints: tuple[int, ...] = ()
  feet: tuple[int, ...] = ()

  def __post_init__(self):
    j = len(self.joint_names)
    if len(self.parents) != j or len(self.twins) != j:
      raise ValueError(f"skeleton {self.name}: joint_names, parents and twins must have equal length")
    for field, low in (("parents", -1), ("twins", 0), ("end_joints", 0), ("feet", 0)):
      if not all(
        isinstance(k, (int, np.integer)) and not isinstance(k, bool) and low <= k < j for k in getattr(self, field)
      ):
        raise ValueError(f"skeleton {self.name}: {field} must be joint indices ({low}..{j - 1})")
    if not all(isinstance(n, str) for n in self.joint_names):
      raise ValueError(f"skeleton {self.name}: joint names must be strings")
    if len(set(self.joint_names)) != j:  # joints are found by name (mapping, retargeting, the add-on)
      twice = next(n for n in self.joint_names if self.joint_names.count(n) > 1)
      raise ValueError(f"skeleton {self.name}: joint name {twice!r} appears twice")
    if not any(p < 0 for p in self.parents):
      raise ValueError(f"skeleton {self.name}: needs a root (a joint whose parent is -1)")
    for i, t in enumerate(self.twins):
      if self.twins[t] != i:
        raise ValueError(f"skeleton {self.name}: twins must be symmetric (joint {i} <-> {t})")
    _ = self.topological_order  # raises on cycles

  @property
  def num_joints(self) -> int:
    return len(self.joint_names)

  @property
  def root(self) -> int:
    """The first root (marker sets have one root per marker: no bones)."""
    return self.parents.index(-1)

  @property
  def bones(self) -> tuple[tuple[int, int], ...]:
    """(parent, child) pairs in topological order."""
    return tuple((self.parents[c], c) for c in self.topological_order if self.parents[c] >= 0)

  @property
  def topological_order(self) -> tuple[int, ...]:
    """Joints ordered so that every parent comes before its children."""
    try:
      return topological_order(self.parents)
    except ValueError:
      raise ValueError(f"skeleton {self.name}: parents do not form a tree") from None

  def to_dict(self) -> dict:
    return dataclasses.asdict(self)

  @classmethod
  def from_dict(cls, d: dict) -> Skeleton:
    fields: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in d.items()}
    return cls(**fields)


@dataclasses.dataclass(frozen=True, eq=False)
class Motion:
  """One take of motion capture as joint positions.

  Attributes:
    positions: ``[T, J, 3]`` float32 joint positions.
    fps: frames per second.
    skeleton: the joint tree.
    up_axis: which axis points up, as a signed axis name: ``y``, ``-y`` (y points down), ``z``.
    units: the length unit of ``positions`` (``m``, ``cm``, ``mm``, ``arbitrary``, ...).
    name: the take's name (file stem by default).
    source: where it was read from (empty if made in memory).
  """

  positions: np.ndarray
  fps: float
  skeleton: Skeleton
  up_axis: str = "y"
  units: str = "arbitrary"
  name: str = ""
  source: str = ""

  def __post_init__(self):
    pos = np.asarray(self.positions, dtype=np.float32)
    if pos.ndim != 3 or pos.shape[1:] != (self.skeleton.num_joints, 3):
      raise ValueError(
        f"{self.source or self.name}: positions must be [T, {self.skeleton.num_joints}, 3], got {pos.shape}"
      )
    pos.setflags(write=False)
    object.__setattr__(self, "positions", pos)

  def __repr__(self) -> str:
    frames, joints = self.positions.shape[:2]
    return (
      f"{type(self).__name__}({self.name!r}: {frames:,} frames at {self.fps:g} fps, {joints} joints"
      f" ({self.skeleton.name}), {self.up_axis} up, {self.units})"
    )

  @property
  def num_frames(self) -> int:
    return self.positions.shape[0]

  def replace(self, **changes) -> Motion:
    return dataclasses.replace(self, **changes)

  def bone_lengths(self) -> np.ndarray:
    """``[T, num_bones]`` lengths of the skeleton's bones."""
    return bone_lengths(self.positions, self.skeleton)


def bone_lengths(positions_TxJx3, skeleton: Skeleton) -> np.ndarray:
  """``[T, num_bones]`` lengths of the skeleton's bones, in ``skeleton.bones`` order."""
  p, c = np.array(skeleton.bones).T
  return np.linalg.norm(positions_TxJx3[:, c] - positions_TxJx3[:, p], axis=-1)


def bone_length_cv(positions: np.ndarray, skeleton: Skeleton, eps: float = 1e-9) -> np.ndarray:
  """Per-bone coefficient of variation (std / mean, ddof=0) of bone lengths over time, ``[num_bones]``.

  The one-number summary chorjax reports ("bone CV") is the MEDIAN over bones of this vector, a
  typical bone; its maximum is reported beside it (marker-based elbows and shoulders wobble most).
  """
  lengths = bone_lengths(positions, skeleton)
  return lengths.std(axis=0) / np.maximum(lengths.mean(axis=0), eps)


def topological_order(parents) -> tuple[int, ...]:
  """Joints ordered so that every parent comes before its children (ValueError if not a tree)."""
  order = []
  frontier = [j for j, p in enumerate(parents) if p < 0]
  while frontier:
    j = frontier.pop(0)
    order.append(j)
    frontier.extend(c for c, p in enumerate(parents) if p == j)
  if len(order) != len(parents):
    raise ValueError("parents do not form a tree")
  return tuple(order)


def mean_bone_lengths(positions_TxJx3, skeleton: Skeleton) -> dict:
  """Child joint -> the mean length of the bone from its parent."""
  return dict(zip([c for _, c in skeleton.bones], bone_lengths(np.asarray(positions_TxJx3), skeleton).mean(0)))


def chain_length(lengths: dict, skeleton: Skeleton, joint: int):
  """The summed ``lengths`` of the bones from ``joint`` up to the root."""
  total = 0.0
  while skeleton.parents[joint] >= 0:
    total, joint = total + lengths[joint], skeleton.parents[joint]
  return total
