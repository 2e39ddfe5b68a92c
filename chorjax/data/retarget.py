"""16-joint motion -> a BVH on any character's hierarchy (``--skeleton CHARACTER.bvh``).

The output keeps the character file's HIERARCHY as it is (joint names, offsets, channel order, rest
pose) and writes new MOTION rows:

- the character's joints are mapped onto the 16-joint layout as training maps them
  (``chorjax.data.mapping``: family, names or topology), measured in its rest pose (every channel 0);
- each mapped joint with one mapped child (hip -> knee, knee -> ankle, shoulder -> elbow, ...) turns by
  the smallest rotation (swing, no twist) that takes its rest direction to the generated one; the
  pelvis and the thorax, with three mapped children each, by the rotation that takes the rest
  left-right line (hips, shoulders) exactly onto the generated one and the spine (neck) into the plane
  it spans with it: unlike a best fit of all three, the facing is kept exactly on any proportions;
- every other joint (fingers, toes, twist bones, the spine joints between pelvis and thorax, the
  clavicles) keeps its rest rotation relative to its parent;
- the root moves with the generated pelvis, scaled by the character's leg length over the generated
  one, its height set so that the generated feet stand on the character's floor (its ankles' height
  standing, from the frames the character file holds); position channels below the root hold their
  rest offsets.

Re-reading the file and mapping it back gives the generated motion's bone directions on the
character's proportions (exactly for the limbs and the left-right lines; the spine and neck within
the plane they span with those).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from chorjax.data.bvh import _POS, _ROT, _parse_hierarchy, forward_kinematics, read_bvh
from chorjax.data.mapping import apply_mapping, find_mapping, leg_length
from chorjax.data.motion import Motion
from chorjax.data.rotations import matrix_to_euler, swing
from chorjax.data.skeletons import MPII16
from chorjax.data.transforms import to_up_axis
from chorjax.errors import UserError, atomic_write, read_text


class Character:
  """A BVH character: its hierarchy text, joints, rest pose and mapping onto the 16 joints."""

  def __init__(self, path):
    self.path = Path(path)
    self.text = read_text(self.path, "BVH")
    if "MOTION" not in self.text:
      raise UserError(f"{self.path}: no MOTION section (a character file is a BVH with its hierarchy)")
    every = _parse_hierarchy(self.path, self.text)  # End Sites included
    row = [j.offset[_POS[c]] if c in _POS else 0.0 for j in every for c in j.channels]
    rest = forward_kinematics(every, np.asarray([row], np.float64))[0]  # rotations 0, offsets as positions
    self.joints = [j for j in every if not j.end]  # the joints with channels, in file order
    new = {k: i for i, k in enumerate(k for k, j in enumerate(every) if not j.end)}
    self.parents = [-1 if j.parent is None else new[j.parent] for j in self.joints]
    self.rest = rest[[k for k, j in enumerate(every) if not j.end]]
    played = read_bvh(self.path)
    sk = played.skeleton
    at = {j.name: rest[k] for k, j in enumerate(every)}
    rest_pose = np.stack([at[n] for n in sk.joint_names])[None].astype(np.float32)
    self.mapping = find_mapping(Motion(rest_pose, 30.0, sk, name=self.path.stem, source=str(self.path)))
    self.index = {j.name: k for k, j in enumerate(self.joints)}
    self.at = at
    self.parent_of = {j.name: every[j.parent].name for j in every if j.parent is not None}
    # its size and floor from the frames it holds (a rest pose need not stand: some rigs lay every bone
    # along x when the rotations are 0)
    self.played = apply_mapping(played, self.mapping).positions.astype(np.float64)
    self.up_axis = "y"

  def target(self, name: str) -> np.ndarray:
    """Rest position of the character joint (or End Site) mapped to 16-joint ``name``."""
    return self.at[self.mapping.joints[name]]

  def leg(self) -> float:
    return leg_length(self.played)

  def floor(self) -> float:
    """The ankles' height standing: the 5th percentile of the lower ankle over its frames (y up)."""
    j = MPII16.joint_names.index
    return float(np.percentile(self.played[:, [j("left_foot"), j("right_foot")], 1].min(-1), 5))


def _drivers(ch: Character) -> dict:
  """Character joint index -> ``(joint, [children])`` of the 16-joint layout whose directions turn it.

  A mapped joint turns toward its mapped children. Where joints lie between a mapped joint and its
  mapped child (a spine between pelvis and thorax, a neck below the head, a clavicle, CMU's hip
  offsets), the first of them turns toward the child along the 16-joint bone, so the bone keeps its
  direction; the others keep their rest rotations."""
  out = {}
  for p, c in MPII16.bones:
    top, end = ch.mapping.joints[MPII16.joint_names[p]], ch.mapping.joints[MPII16.joint_names[c]]
    between = []
    while ch.parent_of.get(end, top) != top:
      end = ch.parent_of[end]
      between.append(end)
    if between:
      out[ch.index[between[-1]]] = (MPII16.joint_names[p], [MPII16.joint_names[c]])
  for t in MPII16.joint_names:
    src = ch.mapping.joints[t]
    kids = [MPII16.joint_names[c] for p, c in MPII16.bones if MPII16.joint_names[p] == t]
    if kids and src in ch.index:  # an End Site has no rotation of its own
      out[ch.index[src]] = (t, kids)
  return out


def retarget(motion: Motion, character: Character) -> np.ndarray:
  """``[T, channels]`` MOTION rows that play ``motion`` (16 joints) on ``character``."""
  if motion.skeleton.joint_names != MPII16.joint_names:
    raise UserError(f"{motion.source or motion.name}: retargeting takes the 16-joint layout")
  gen = np.asarray(to_up_axis(motion, character.up_axis).positions, np.float64)
  g = {n: gen[:, k] for k, n in enumerate(MPII16.joint_names)}
  t = gen.shape[0]
  drivers = _drivers(character)
  glob = np.zeros((t, len(character.joints), 3, 3))
  eye = np.broadcast_to(np.eye(3), (t, 3, 3))
  for k, p in enumerate(character.parents):  # parents come first in a BVH
    parent = eye if p < 0 else glob[:, p]
    if k not in drivers:
      glob[:, k] = parent  # rest rotation relative to the parent
      continue
    name, kids = drivers[k]
    rest = np.stack([character.target(c) - character.rest[k] for c in kids])
    obs = np.stack([g[c] - g[name] for c in kids], axis=1)
    if len(kids) == 1:
      glob[:, k] = swing(np.einsum("tij,j->ti", parent, rest[0]), obs[:, 0]) @ parent
    else:  # pelvis, thorax: the left-right line exactly, the spine or neck in the plane it spans
      side = {c.split("_")[0]: i for i, c in enumerate(kids)}
      left, right, mid = side["left"], side["right"], next(i for i, c in enumerate(kids) if "_" not in c)
      turn = _frame(obs[:, left] - obs[:, right], obs[:, mid]) @ _frame(rest[left] - rest[right], rest[mid]).T
      glob[:, k] = turn
  scale = character.leg() / leg_length(gen)
  up = np.eye(3)[1]  # BVH is y-up
  floor = np.percentile(np.minimum(g["left_foot"] @ up, g["right_foot"] @ up), 5)  # ankles standing
  pelvis_at = g["pelvis"] * scale
  pelvis_at += np.outer((g["pelvis"] @ up - floor) * scale + character.floor() - pelvis_at @ up, up)  # its floor
  root = character.joints[0]
  cols = []
  for k, j in enumerate(character.joints):
    parent = eye if character.parents[k] < 0 else glob[:, character.parents[k]]
    local = np.swapaxes(parent, -1, -2) @ glob[:, k]
    rot_order = "".join(_ROT[c] for c in j.channels if c in _ROT)
    angles = matrix_to_euler(local, rot_order) if rot_order else np.zeros((t, 0))
    pos = np.broadcast_to(j.offset, (t, 3)).copy()
    if j is root:  # the generated pelvis, on the character's scale, where the root is above it
      pelvis = character.target("pelvis") - character.rest[0]
      pos = pelvis_at - np.einsum("tij,j->ti", glob[:, 0], pelvis)
    values = {c: pos[:, _POS[c]] for c in j.channels if c in _POS}
    values.update({c: angles[:, rot_order.index(_ROT[c])] for c in j.channels if c in _ROT})
    cols += [values[c] for c in j.channels]
  return np.stack(cols, axis=1) if cols else np.zeros((t, 0))


def _frame(across, along) -> np.ndarray:
  """An orthonormal frame (columns): x along ``across``, y along ``along`` made perpendicular to it."""
  x = across / np.linalg.norm(across, axis=-1, keepdims=True)
  y = along - np.sum(along * x, -1, keepdims=True) * x
  y = y / np.maximum(np.linalg.norm(y, axis=-1, keepdims=True), 1e-12)
  return np.stack([x, y, np.cross(x, y)], axis=-1)


def write_retargeted(motion: Motion, character, path, *, overwrite: bool = True) -> Path:
  """Writes ``motion`` (16 joints) as a BVH on ``character`` (a ``Character`` or its BVH file; see the
  module docstring)."""
  character = character if isinstance(character, Character) else Character(character)
  rows = retarget(motion, character)
  head = character.text[: character.text.index("MOTION")].rstrip("\r\n ")
  lines = [head, "MOTION", f"Frames: {rows.shape[0]}", f"Frame Time: {1.0 / motion.fps:.8f}"]
  body = "\n".join(" ".join(f"{v:.6f}" for v in row) for row in rows)
  text = "\n".join(lines) + "\n" + body + "\n"
  return atomic_write(path, lambda p: p.write_text(text), overwrite=overwrite)
