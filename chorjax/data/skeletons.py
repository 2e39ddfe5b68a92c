"""Named skeletons. ``mpii16`` is the 16-joint layout of the bundled CMU subject 94 takes."""

from __future__ import annotations

from chorjax.data.motion import Skeleton
from chorjax.errors import UserError

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
  """Looks up a named skeleton; a ``UserError`` lists the known names."""
  try:
    return SKELETONS[name]
  except KeyError:
    raise UserError(f"unknown skeleton {name!r}; known: {', '.join(sorted(SKELETONS))}") from None
