"""A chorjax dance (16 joint positions a frame) onto any humanoid armature, inside Blender.

The armature's parts are found by their bones' names (``joint_names.split_name``, the rules chorjax reads a
take's joints with: Mixamo, HumanIK, Rigify ``DEF-thigh.L``, ...). Each frame the hips take the dance's pelvis
(position and the frame of the two hips), the chest the frame of the two shoulders, and the thighs, shins,
upper arms, forearms, neck and head turn, each by the smallest rotation, to point where the dance's bone
points; the other bones follow their parents. Positions are scaled by leg length onto the armature, so any
figure's proportions keep the dance's directions and its path over the floor.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from mathutils import Matrix, Quaternion, Vector

from .joint_names import SYNONYMS, split_name

SHIPPED = json.loads(Path(__file__).with_name("chorjax.json").read_text())
MPII16 = SHIPPED["joints"]  # the 16-joint layout every chorjax output is in
# (bone, from joint, to joint): the bone turns to point along the dance's from -> to. A limb bone is named
# after the joint at its head (the thigh is "left_hip"), as the 16 joints are.
LIMBS = [("hip", "knee"), ("knee", "foot"), ("shoulder", "elbow"), ("elbow", "hand")]
AIMS = [(f"{s}_{a}", f"{s}_{a}", f"{s}_{b}") for s in ("left", "right") for a, b in LIMBS]
AIMS += [("neck", "thorax", "neck"), ("head", "neck", "head_top")]
FRAMED = {"pelvis": "hip", "thorax": "shoulder"}  # bones turned as the frame of the two hips / shoulders
LIMB_ROLES = {"hip": "hip", "knee": "knee", "foot": "ankle", "shoulder": "shoulder", "elbow": "elbow", "hand": "wrist"}


FEET = [MPII16.index("left_foot"), MPII16.index("right_foot")]


def on_floor(positions_Tx16x3: np.ndarray, floor: float | None = None) -> np.ndarray:
  """The dance (Blender's axes) moved up or down so that its floor is at z = 0: ``floor``, the training floor's
  height where the run knows it (``chorjax live``'s hello), else the median height of its lower foot (where a
  dance's feet are most of the time). A y-down take's floor is where its y is largest: turned to z up as it
  is, a quickstart sample stood 3 m under Blender's floor."""
  p = np.array(positions_Tx16x3, np.float64)
  p[..., 2] -= float(np.median(p[:, FEET, 2].min(-1))) if floor is None else floor
  return p


class DanceError(Exception):
  """A file or an armature the add-on cannot use; its message is one line for Blender's status bar."""


def to_blender(positions, up_axis: str) -> np.ndarray:
  """Positions whose up axis is ``up_axis`` -> Blender's axes (z up, -y forward), as its glTF importer does."""
  if up_axis not in SHIPPED["y_up"]:
    raise DanceError(f"unknown up axis {up_axis!r}; known: {', '.join(SHIPPED['y_up'])}")
  y_up = np.asarray(positions, np.float64) @ np.asarray(SHIPPED["y_up"][up_axis]).T
  return np.stack([y_up[..., 0], -y_up[..., 2], y_up[..., 1]], -1)


def read_dance(path, fps: float = 30.0, up_axis: str = "-y", dancer: int = 0) -> tuple[np.ndarray, float]:
  """A chorjax output's ``[T, 16, 3]`` positions in Blender's axes, standing on z = 0 (:func:`on_floor`), and its
  frame rate.

  ``.npz`` (``[K, T, 16, 3]``: K dancers, ``dancer`` picks one) carries its frame rate and up axis; a ``.csv``
  of the 16-joint layout does not (``fps`` and ``up_axis`` say them: chorjax's CSV default is ``-y``, y
  pointing down) unless a sidecar is beside it.
  """
  path = Path(path)
  try:
    if path.suffix.lower() == ".npz":
      with np.load(path, allow_pickle=False) as data:
        meta, positions = json.loads(str(data["meta"])), np.asarray(data["positions"], np.float64)
      if positions.ndim == 4 and not 0 <= dancer < len(positions):
        raise DanceError(f"{path.name}: dancer {dancer} asked for; it holds {len(positions)} (0-{len(positions) - 1})")
      positions = positions[dancer] if positions.ndim == 4 else positions
      names, fps, up_axis = meta["skeleton"]["joint_names"], float(meta["fps"]), meta["up_axis"]
    elif path.suffix.lower() == ".csv":
      sidecar = path.with_name(path.stem + ".skeleton.json")
      meta = json.loads(sidecar.read_text()) if sidecar.exists() else None
      names = meta["skeleton"]["joint_names"] if meta else MPII16
      fps, up_axis = (float(meta["fps"]), meta["up_axis"]) if meta else (fps, up_axis)
      positions = np.loadtxt(path, delimiter=",", ndmin=2).reshape(-1, len(names), 3)
    else:
      raise DanceError(f"{path.name}: chorjax's .npz or .csv (the 16-joint layout) expected")
  except (OSError, ValueError, KeyError) as e:
    raise DanceError(f"{path.name}: not a chorjax dance ({e})") from None
  if list(names) != MPII16:
    raise DanceError(f"{path.name}: not in the 16-joint layout (joints {', '.join(names[:4])}, ...)")
  if positions.ndim != 3 or not np.isfinite(positions).all():
    raise DanceError(f"{path.name}: positions must be [frames, 16, 3] finite numbers")
  return on_floor(to_blender(positions, up_axis)), fps


def _common_parent(a, b):
  above = [a]
  while above[-1].parent is not None:
    above.append(above[-1].parent)
  while b is not None and b not in above:
    b = b.parent
  return b


def _frame(across: Vector, up: Vector) -> Quaternion:
  """The rotation whose x axis is ``across`` and z axis ``up`` made square to it."""
  x = across.normalized()
  z = (up - up.dot(x) * x).normalized()
  return Matrix((x, z.cross(x), z)).transposed().to_quaternion()


class Rig:
  """The parts of one armature and its rest pose, to pose it from dance frames (``pose`` / ``keyframe``)."""

  def __init__(self, armature_object):
    self.object, bones = armature_object, armature_object.data.bones
    parts = {}
    for side in ("left", "right"):
      for role, synonym_role in LIMB_ROLES.items():
        parts[f"{side}_{role}"] = _named(bones, side, SYNONYMS[synonym_role])
    parts["neck"], parts["head"] = _named(bones, None, ("neck",)), _named(bones, None, ("head",))
    missing = [k for k, v in parts.items() if v is None]
    if missing:
      raise DanceError(f"{armature_object.name}: no bone found for {', '.join(missing)} (a humanoid's bone names)")
    parts["pelvis"] = _common_parent(parts["left_hip"], parts["right_hip"])
    parts["thorax"] = _common_parent(parts["left_shoulder"], parts["right_shoulder"])
    if parts["pelvis"] is None or parts["thorax"] is None:
      raise DanceError(f"{armature_object.name}: the legs (or the arms) do not meet in one bone")
    self.parts = {k: v.name for k, v in parts.items()}
    rest = {k: Vector(v.head_local) for k, v in parts.items() if k not in ("neck", "head", "thorax")}
    rest.update(thorax=Vector(parts["neck"].head_local), neck=Vector(parts["head"].head_local))
    rest["head_top"] = Vector(parts["head"].tail_local)
    self.rest = rest  # the armature's joints at rest, in the armature's space, by chorjax joint name
    self.leg = _leg(rest)
    self.order = _parents_first(bones)

  def joints(self, frame_Jx3: np.ndarray, scale: float) -> dict:
    """A dance frame (Blender's world axes) in the armature's space, scaled: chorjax joint name -> Vector."""
    turn = self.object.matrix_world.to_quaternion().inverted()
    return {name: turn @ Vector(p * scale) for name, p in zip(MPII16, frame_Jx3)}

  def scale(self, positions_Tx16x3: np.ndarray) -> float:
    """Armature units per dance unit: the ratio of the two figures' leg lengths."""
    every = positions_Tx16x3[:: max(len(positions_Tx16x3) // 50, 1)]
    dance = np.mean([_leg({n: Vector(p) for n, p in zip(MPII16, frame)}) for frame in every])
    return self.leg / max(float(dance), 1e-12)

  def pose(self, joints: dict) -> dict:
    """Bone name -> (location, rotation quaternion) that put the armature in the dance's pose ``joints``."""
    turned = {
      part: _frame(joints[f"left_{side}"] - joints[f"right_{side}"], joints["thorax"] - joints["pelvis"])
      @ _frame(
        self.rest[f"left_{side}"] - self.rest[f"right_{side}"], self.rest["thorax"] - self.rest["pelvis"]
      ).inverted()
      for part, side in FRAMED.items()
    }
    aims = {self.parts[role]: (a, b) for role, a, b in AIMS}
    framed = {self.parts[part]: part for part in FRAMED}
    posed, out = {}, {}
    for bone in self.order:
      rest = bone.matrix_local
      inherit = posed[bone.parent.name] @ bone.parent.matrix_local.inverted() @ rest if bone.parent else rest.copy()
      now, loc = inherit.to_quaternion(), Vector()
      if bone.name in framed:
        target = turned[framed[bone.name]] @ rest.to_quaternion()
        if framed[bone.name] == "pelvis":  # the hips also go where the dance's pelvis is
          loc = now.inverted() @ (joints["pelvis"] - inherit.translation)
      elif bone.name in aims:
        a, b = aims[bone.name]
        was = now @ rest.to_quaternion().inverted() @ (self.rest[b] - self.rest[a])
        target = was.rotation_difference(joints[b] - joints[a]) @ now
      else:
        posed[bone.name] = inherit
        continue
      turn = now.inverted() @ target
      out[bone.name] = (loc, turn)
      posed[bone.name] = inherit @ Matrix.Translation(loc) @ turn.to_matrix().to_4x4()
    return out

  def apply(self, pose: dict) -> None:
    """Sets the pose bones (live): every bone this rig drives, the others left as they are."""
    for name, (loc, turn) in pose.items():
      bone = self.object.pose.bones[name]
      bone.rotation_mode = "QUATERNION"
      bone.location, bone.rotation_quaternion = loc, turn

  def keyframe(self, positions_Tx16x3: np.ndarray, first_frame: int = 1, name: str = "chorjax") -> int:
    """Bakes a whole dance as one new action on the armature, a key per frame from ``first_frame``."""
    scale = self.scale(positions_Tx16x3)
    poses = [self.pose(self.joints(frame, scale)) for frame in positions_Tx16x3]
    action = _new_action(self.object, name)
    times = np.arange(first_frame, first_frame + len(poses), dtype=np.float64)
    for bone in poses[0]:
      self.object.pose.bones[bone].rotation_mode = "QUATERNION"
      paths = [("location", 0)] if bone == self.parts["pelvis"] else []
      for path, which in [*paths, ("rotation_quaternion", 1)]:
        values = np.array([list(p[bone][which]) for p in poses], np.float64)
        for axis in range(values.shape[1]):
          curve = action.fcurves.new(f'pose.bones["{bone}"].{path}', index=axis, action_group=bone)
          curve.keyframe_points.add(len(times))
          curve.keyframe_points.foreach_set("co", np.stack([times, values[:, axis]], -1).ravel())
          curve.update()
    return len(poses)


def _new_action(armature_object, name: str):
  import bpy

  action = bpy.data.actions.new(name)
  if armature_object.animation_data is None:
    armature_object.animation_data_create()
  armature_object.animation_data.action = action
  return action


def _named(bones, side, synonyms):
  split = {b.name: split_name(b.name) for b in bones}
  for synonym in synonyms:
    hits = [b for b in bones if split[b.name] == (side, synonym, False)]
    if hits:
      return hits[0]
  return None


def _leg(points: dict) -> float:
  """The mean length of the two legs (hip to knee to ankle)."""
  sides = [
    (points[f"{s}_hip"] - points[f"{s}_knee"]).length + (points[f"{s}_knee"] - points[f"{s}_foot"]).length
    for s in ("left", "right")
  ]
  return float(np.mean(sides))


def _parents_first(bones) -> list:
  order, todo = [], [b for b in bones if b.parent is None]
  while todo:
    bone = todo.pop(0)
    order.append(bone)
    todo.extend(bone.children)
  return order
