"""Named skeletons. ``mpii16`` is the 16-joint layout of the bundled CMU subject 94 takes."""

from __future__ import annotations

import json
from pathlib import Path

from chorjax.data.motion import Skeleton
from chorjax.errors import UserError, check_rate, check_up_axis, load_json, read_text

# Joint order as in the cmu94 CSV files (see bundled/cmu94/SOURCES.md).
_MPII16_NAMES = (
  "right_foot",
  "right_knee",
  "right_hip",
  "left_hip",
  "left_knee",
  "left_foot",
  "pelvis",
  "thorax",
  "neck",
  "head_top",
  "right_hand",
  "right_elbow",
  "right_shoulder",
  "left_shoulder",
  "left_elbow",
  "left_hand",
)
# Bones (parent, child) from SOURCES.md, converted to 0-based indices; pelvis (6) is the root.
_MPII16_BONES = (
  (6, 2),
  (2, 1),
  (1, 0),
  (6, 3),
  (3, 4),
  (4, 5),
  (6, 7),
  (7, 8),
  (8, 9),
  (7, 12),
  (12, 11),
  (11, 10),
  (7, 13),
  (13, 14),
  (14, 15),
)


def _parents_from_bones(num_joints: int, bones) -> tuple[int, ...]:
  parents = [-1] * num_joints
  for p, c in bones:
    parents[c] = p
  return tuple(parents)


def _twins_from_names(names) -> tuple[int, ...]:
  index = {n: i for i, n in enumerate(names)}

  def twin(n):
    for a, b in (("left", "right"), ("right", "left")):
      if n.startswith(a):
        return index[b + n[len(a) :]]
    return index[n]

  return tuple(twin(n) for n in names)


MPII16 = Skeleton(
  name="mpii16",
  joint_names=_MPII16_NAMES,
  parents=_parents_from_bones(16, _MPII16_BONES),
  twins=_twins_from_names(_MPII16_NAMES),
  end_joints=(0, 5, 9, 10, 15),
  feet=(0, 5),
)

SKELETONS = {"mpii16": MPII16}


def get_skeleton(name: str) -> Skeleton:
  """A named skeleton, or the one in a skeleton file (a CSV's ``.skeleton.json`` sidecar); a
  ``UserError`` lists the known names."""
  if name in SKELETONS:
    return SKELETONS[name]
  if name.endswith(".json"):
    if not Path(name).is_file():
      raise UserError(f"data.skeleton: {name}: no such skeleton file")
    return read_sidecar(name)[0]
  raise UserError(f"unknown skeleton {name!r}; known: {', '.join(sorted(SKELETONS))}, or a .skeleton.json file")


def read_sidecar(path) -> tuple[Skeleton, float, str, str]:
  """``(skeleton, fps, up_axis, units)`` from a skeleton sidecar (or any JSON holding a ``skeleton``)."""
  path = Path(path)
  try:
    data = load_json(read_text(path, "skeleton JSON"))
    sk = Skeleton.from_dict(data.get("skeleton", data))
    fps, up, units = data.get("fps", 30.0), data.get("up_axis", "y"), str(data.get("units", "arbitrary"))
    if isinstance(fps, bool) or not isinstance(fps, int | float):  # "30" or true: not what a writer writes
      raise ValueError(f"fps: expected a number, got {fps!r}")
  except (json.JSONDecodeError, KeyError, TypeError, ValueError, AttributeError) as e:
    raise UserError(f"{path}: not a skeleton file ({type(e).__name__}: {e})") from None
  return sk, check_rate(fps, f"{path}: fps"), check_up_axis(up, f"{path}: up_axis"), units
