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


# Named joint mappings into the 16-joint training layout: target joint -> source joint name.
# cmu_asf: CMU ASF/AMC files (joints named after the bone that ends there).
# cmu_bvh: CMU BVH conversions (bvh11/cgspeed naming, End Sites as <joint>_end).
# bandai: Bandai Namco Research Motiondataset BVH files. Their head End Site has a zero offset (no head
#   top), so thorax/neck/head_top take the Chest, Neck and Head joints: the head ends at its base.
MAPPINGS = {
  "cmu_asf": {
    "right_foot": "rtibia",
    "right_knee": "rfemur",
    "right_hip": "rhipjoint",
    "left_hip": "lhipjoint",
    "left_knee": "lfemur",
    "left_foot": "ltibia",
    "pelvis": "root",
    "thorax": "thorax",
    "neck": "upperneck",
    "head_top": "head",
    "right_hand": "rradius",
    "right_elbow": "rhumerus",
    "right_shoulder": "rclavicle",
    "left_shoulder": "lclavicle",
    "left_elbow": "lhumerus",
    "left_hand": "lradius",
  },
  "cmu_bvh": {
    "right_foot": "RightAnkle",
    "right_knee": "RightKnee",
    "right_hip": "RightHip",
    "left_hip": "LeftHip",
    "left_knee": "LeftKnee",
    "left_foot": "LeftAnkle",
    "pelvis": "Hips",
    "thorax": "Chest2",
    "neck": "Head",
    "head_top": "Head_end",
    "right_hand": "RightWrist",
    "right_elbow": "RightElbow",
    "right_shoulder": "RightShoulder",
    "left_shoulder": "LeftShoulder",
    "left_elbow": "LeftElbow",
    "left_hand": "LeftWrist",
  },
  "bandai": {
    "right_foot": "Foot_R",
    "right_knee": "LowerLeg_R",
    "right_hip": "UpperLeg_R",
    "left_hip": "UpperLeg_L",
    "left_knee": "LowerLeg_L",
    "left_foot": "Foot_L",
    "pelvis": "Hips",
    "thorax": "Chest",
    "neck": "Neck",
    "head_top": "Head",
    "right_hand": "Hand_R",
    "right_elbow": "LowerArm_R",
    "right_shoulder": "UpperArm_R",
    "left_shoulder": "UpperArm_L",
    "left_elbow": "LowerArm_L",
    "left_hand": "Hand_L",
  },
}


def find_mapping(skeleton: Skeleton) -> str | None:
  """The name of the first mapping whose source joints all exist in ``skeleton``."""
  names = set(skeleton.joint_names)
  return next((k for k, m in MAPPINGS.items() if set(m.values()) <= names), None)


def to_mpii16(motion):
  """Maps a motion of a known skeleton (see ``MAPPINGS``) onto the 16-joint training layout."""
  if motion.skeleton.joint_names == MPII16.joint_names:
    return motion
  key = find_mapping(motion.skeleton)
  if key is None:
    raise UserError(
      f"{motion.source or motion.name}: no joint mapping from skeleton {motion.skeleton.name!r} "
      f"({motion.skeleton.num_joints} joints) to mpii16 (known: {', '.join(MAPPINGS)}); "
      "train on its own skeleton with data.joints='native'"
    )
  index = {n: i for i, n in enumerate(motion.skeleton.joint_names)}
  cols = [index[MAPPINGS[key][n]] for n in MPII16.joint_names]
  return motion.replace(positions=motion.positions[:, cols], skeleton=MPII16)
