"""Any skeleton onto the 16-joint training layout: by a known family, by joint names, by topology, or by file.

``find_mapping`` tries, in order:

1. a mapping file (``data.joint_map`` / ``--joint-map``), when one is given: one line per target joint,
   ``left_knee = "LeftLeg"``;
2. a known family whose names mean something else than usual (CMU ASF names a joint after the bone
   that ENDS there: ``lfemur`` is the knee);
3. **names**: each joint name is normalized (namespace prefixes such as ``mixamorig:`` dropped, case and
   separators ignored, the side read from ``Left``/``L``/``_l``/``.L``/``ShoulderLeft`` markers) and
   matched against synonyms (UpLeg/UpperLeg/Thigh/Hip, Leg/Knee/Shin/LowerLeg, Ankle/Foot,
   ForeArm/Elbow/LowerArm, Wrist/Hand, Arm/UpperArm/Shoulder). Structure settles what names leave open:
   the pelvis is where the two legs meet, the thorax where the two arms meet, a missing knee or
   shoulder is the joint above the ankle or elbow, and the head joint is the neck point when a head top
   sits above it (else the head top, with the neck below). A head with eyes but nothing above them (an
   acLSTM/Poser rig) gets a derived head top, ``HEAD_TOP_FROM_EYES`` (see ``with_head_top``). This
   covers MotionBuilder/HumanIK, Mixamo, the CMU converters, LaFAN1/Ubisoft, SMPL/AIST++, Kinect v2 and
   Bandai Namco namings;
4. **topology** alone, when names say nothing: two leg chains downward from the root, two arm chains
   and a head chain from the spine; the thigh/shin and upper arm/forearm are the two longest
   consecutive bones of each limb; left is ``up x forward`` (right-handed coordinates), forward the
   way the toes point.

Every mapping is checked: the mapped joints must form the expected chains from the root (hip above
knee above ankle, thorax above shoulders and neck, the two sides apart). What was chosen is a
``Mapping``: printed by training and ``data check``, and recorded in every run's meta.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from chorjax.data.joint_names import SYNONYMS, split_name
from chorjax.data.motion import Motion
from chorjax.data.skeletons import MPII16
from chorjax.errors import UserError, read_toml

TARGETS = MPII16.joint_names

# Known rigs, by the joint names they use. CMU ASF/AMC: joints are named after the bone that ends there.
FAMILIES = {
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
  # chorjax's own 16 joints, as its BVH and CSV writers name them: a file chorjax wrote reads back as it was.
  "chorjax": {name: name for name in TARGETS},
}

HEAD_TOP_FROM_EYES = "head_top_from_eyes"  # a derived joint: see with_head_top
_HEAD_TOPS = ("headtop", "headend", "headtopend", "headnub", "headsite", "headtip", "headtopend1", "headtopfromeyes")
_PARTS = {  # target name -> (side, role)
  f"{side}_{part}": (side, role)
  for side in ("left", "right")
  for part, role in (
    ("foot", "ankle"),
    ("knee", "knee"),
    ("hip", "hip"),
    ("hand", "wrist"),
    ("elbow", "elbow"),
    ("shoulder", "shoulder"),
  )
}


@dataclasses.dataclass(frozen=True)
class Mapping:
  """Which source joint gives each of the 16 target joints, and how that was decided.

  Attributes:
    method: ``file:PATH``, a family name (``cmu_asf``), ``names`` or ``topology``.
    joints: target joint name -> source joint name, in ``MPII16.joint_names`` order.
  """

  method: str
  joints: dict

  def describe(self) -> str:
    pairs = ", ".join(f"{t}={s}" for t, s in self.joints.items())
    return f"by {self.method}: {pairs}"

  def to_dict(self) -> dict:
    return {"method": self.method, "joints": dict(self.joints)}


def read_joint_map(path) -> dict:
  """A mapping file: TOML, one ``target = "source joint"`` line per target joint (all 16)."""
  path = Path(path)
  data = read_toml(path, "joint-map")
  data = data.get("joints", data)
  unknown = [k for k in data if k not in TARGETS]
  if unknown:
    raise UserError(f"{path}: unknown target joint {unknown[0]!r}; targets: {', '.join(TARGETS)}")
  bad = [k for k, v in data.items() if not isinstance(v, str)]
  if bad:
    raise UserError(f"{path}: {bad[0]} must name one source joint as a string")
  return dict(data)


class _Tree:
  """A skeleton with mean joint distances, for walking up and down chains."""

  def __init__(self, motion: Motion):
    sk = motion.skeleton
    self.names, self.parents = sk.joint_names, sk.parents
    self.children = {j: [c for c, p in enumerate(sk.parents) if p == j] for j in range(sk.num_joints)}
    pos = np.asarray(motion.positions[:: max(motion.num_frames // 200, 1)], np.float64)
    self.pos = pos
    self.length = np.array(
      [np.linalg.norm(pos[:, j] - pos[:, max(p, 0)], axis=-1).mean() for j, p in enumerate(sk.parents)]
    )
    body = np.sort(self.length)[-max(len(self.length) // 3, 1) :].mean()
    self.tiny = 0.05 * body

  def ancestors(self, j: int) -> list[int]:
    return _ancestors(self.parents, j)

  def up(self, j: int) -> int | None:
    """The nearest ancestor at a distance (skips joints that sit on top of ``j``)."""
    for a in self.ancestors(j):
      if np.linalg.norm(self.pos[:, j] - self.pos[:, a], axis=-1).mean() > self.tiny:
        return a
    return None

  def lca(self, a: int, b: int) -> int | None:
    up_a = [a, *self.ancestors(a)]
    return next((x for x in [b, *self.ancestors(b)] if x in up_a), None)

  def dist(self, a: int, b: int) -> float:
    return float(np.linalg.norm(self.pos[:, a] - self.pos[:, b], axis=-1).mean())


def _by_names(tree: _Tree) -> dict | None:
  split = [split_name(n) for n in tree.names]
  found: dict[str, int] = {}

  def named(side, role):
    for syn in SYNONYMS[role]:
      hit = [j for j, (s, b, e) in enumerate(split) if s == side and b == syn and not e]
      if hit:
        return hit[0]
    return None

  for side in ("left", "right"):
    for end, mid, top in (("ankle", "knee", "hip"), ("wrist", "elbow", "shoulder")):
      below = named(side, end)
      if below is None:
        return None
      found[f"{side}_{end}"] = below
      for role in (mid, top):  # a name above the joint below, else the joint above it
        j = named(side, role)
        j = j if j is not None and j in tree.ancestors(below) else tree.up(below)
        if j is None:
          return None
        found[f"{side}_{role}"] = below = j
  pelvis = tree.lca(found["left_hip"], found["right_hip"])
  thorax = tree.lca(found["left_shoulder"], found["right_shoulder"])
  heads = [j for j, (s, b, e) in enumerate(split) if s is None and b == "head" and not e]
  if pelvis is None or thorax is None or not heads:
    return None
  neck, top = _neck_and_top(tree, heads[0], split)
  return _assemble(tree, found, pelvis, thorax, neck, top)


def _neck_and_top(tree: _Tree, head: int, split) -> tuple[int, int]:
  below = _descendants(tree, head)
  tops = [j for j in below if split[j][1] in _HEAD_TOPS or (split[j][2] and split[j][1] == "head")]
  if not tops:
    leaves = [j for j in below if not tree.children[j] and split[j][1] != "eye"]
    tops = sorted(leaves, key=lambda j: -tree.dist(head, j))[:1]
  top = next((j for j in tops if tree.dist(head, j) > tree.tiny), None)
  if top is None:  # no head top above the head joint (Bandai, Kinect): the head joint is the top
    return tree.up(head) or head, head
  return head, top


def _descendants(tree: _Tree, j: int) -> list[int]:
  out, todo = [], list(tree.children[j])
  while todo:
    k = todo.pop(0)
    out.append(k)
    todo.extend(tree.children[k])
  return out


def _assemble(tree: _Tree, limbs: dict, pelvis: int, thorax: int, neck: int, top: int) -> dict:
  j = {f"{s}_{part}": limbs[f"{s}_{role}"] for s in ("left", "right") for part, role in _ROLE_OF.items()}
  j.update(pelvis=pelvis, thorax=thorax, neck=neck, head_top=top)
  return {t: tree.names[j[t]] for t in TARGETS}


_ROLE_OF = {"foot": "ankle", "knee": "knee", "hip": "hip", "hand": "wrist", "elbow": "elbow", "shoulder": "shoulder"}


def _by_topology(tree: _Tree, up_axis: str) -> dict | None:
  up = np.zeros(3)
  up["xyz".index(up_axis[-1])] = -1.0 if up_axis.startswith("-") else 1.0
  height = lambda j: float((tree.pos[:, j] @ up).mean())
  root = tree.parents.index(-1)
  pelvis = root
  while len(tree.children[pelvis]) == 1:
    pelvis = tree.children[pelvis][0]
  kids = tree.children[pelvis]
  if len(kids) < 3:
    return None
  subtree_height = lambda k: np.mean([height(x) for x in [k, *_descendants(tree, k)]])
  kids = sorted(kids, key=subtree_height)
  legs, spine = kids[:2], kids[-1]
  thorax = next((x for x in [spine, *_descendants(tree, spine)] if len(tree.children[x]) >= 3), None)
  if thorax is None:
    return None
  upper = sorted(tree.children[thorax], key=subtree_height)
  head_root, arms = upper[-1], sorted(upper[:-1], key=lambda k: -_reach(tree, thorax, k))[:2]
  limbs = [_limb(tree, pelvis, k) for k in legs] + [_limb(tree, thorax, k) for k in arms]
  chains = [c for c in limbs if c is not None]
  if len(chains) != 4:
    return None
  forward = np.zeros(3)
  for hip, knee, ankle, after in chains[:2]:
    step = (
      tree.pos[:, after] - tree.pos[:, ankle]
      if after is not None
      else tree.pos[:, knee] - (tree.pos[:, hip] + tree.pos[:, ankle]) / 2
    )
    forward += step.mean(0) - (step.mean(0) @ up) * up
  left = np.cross(up, forward)
  found = {}
  for (a, b, c, _), base in zip(chains, (pelvis, pelvis, thorax, thorax)):
    side = "left" if ((tree.pos[:, a] - tree.pos[:, base]).mean(0) @ left) > 0 else "right"
    roles = ("hip", "knee", "ankle") if base == pelvis else ("shoulder", "elbow", "wrist")
    found.update({f"{side}_{r}": j for r, j in zip(roles, (a, b, c))})
  if len(found) != 12:
    return None
  head_path = _deepest_path(tree, head_root, key=height)
  path = [j for j in head_path if tree.dist(j, thorax) > tree.tiny]
  if len(path) < 2:
    return None
  top = next(j for j in reversed(path) if tree.dist(j, tree.parents[j]) > tree.tiny)
  neck = tree.up(top)
  if neck is None:
    return None
  return _assemble(tree, found, pelvis, thorax, neck, top)


def _reach(tree: _Tree, base: int, k: int) -> float:
  return max(tree.dist(base, x) for x in [k, *_descendants(tree, k)])


def _deepest_path(tree: _Tree, start: int, key) -> list[int]:
  """The path from ``start`` to its leaf with the largest ``key``."""
  leaves = [x for x in [start, *_descendants(tree, start)] if not tree.children[x]]
  path = [max(leaves, key=key)]
  while path[-1] != start:
    path.append(tree.parents[path[-1]])
  return path[::-1]


def _limb(tree: _Tree, base: int, start: int):
  """(root joint, middle joint, end joint, the next joint or None) of the limb below ``start``, on the
  path from ``base`` to the farthest leaf: the thigh and shin (upper arm and forearm) are the two longest
  consecutive bones, the later pair where two pairs are within 10% (a long clavicle before the arm)."""
  path = [base, *_deepest_path(tree, start, key=lambda x: tree.dist(base, x))]
  path = [j for k, j in enumerate(path) if k == 0 or tree.dist(j, path[k - 1]) > tree.tiny]
  if len(path) < 4:
    return None
  bones = [tree.dist(path[k], path[k + 1]) for k in range(len(path) - 1)]
  pairs = [bones[i] + bones[i + 1] for i in range(len(bones) - 1)]
  k = max(i for i, x in enumerate(pairs) if x >= 0.9 * max(pairs))
  return path[k], path[k + 1], path[k + 2], (path[k + 3] if k + 3 < len(path) else None)


def with_head_top(motion: Motion) -> Motion:
  """``motion`` plus a derived head-top joint (``HEAD_TOP_FROM_EYES``, a child of the head) where the head has
  two eyes and no joint or End Site above them; otherwise ``motion`` itself.

  The 16-joint layout's head top is where CMU's head bone ends (its ASF head bone is about as long as the
  upper neck: roughly eye level, well below the crown). On a rig without that point (acLSTM's takes: the
  ``head`` joint sits at the base of the skull, its only children are the eyes) it is put at the eyes'
  height along the neck -> head direction, turned with the head: the head's own frame is read from the
  head and eye positions in every frame (lateral: eye to eye; up: towards the eyes), and the direction is
  the neck -> head direction's mean in that frame.
  """
  sk = motion.skeleton
  if HEAD_TOP_FROM_EYES in sk.joint_names or not sk.bones:
    return motion
  split = [split_name(n) for n in sk.joint_names]
  heads = [j for j, (side, base, end) in enumerate(split) if side is None and base == "head" and not end]
  if not heads or sk.parents[heads[0]] < 0:
    return motion
  head = heads[0]
  below = [j for j in range(sk.num_joints) if head in _ancestors(sk.parents, j)]
  eyes = {split[j][0]: j for j in below if split[j][1] == "eye" and not split[j][2]}
  above = [j for j in below if split[j][1] != "eye" and split[j][1] != "" and not split[j][1].endswith("eye")]
  if set(eyes) != {"left", "right"} or above:
    return motion
  p = np.asarray(motion.positions, np.float64)
  base, top_of_neck = p[:, sk.parents[head]], p[:, head]
  x = _unit(p[:, eyes["left"]] - p[:, eyes["right"]])
  rise = (p[:, eyes["left"]] + p[:, eyes["right"]]) / 2 - top_of_neck
  y = _unit(rise - (rise * x).sum(-1, keepdims=True) * x)
  frame = np.stack([x, y, np.cross(x, y)], axis=-1)  # [T, 3, 3]: columns are the head's axes
  axis = _unit(top_of_neck - base)
  local = _unit(np.einsum("tji,tj->ti", frame, axis).mean(0))
  height = float((rise * axis).sum(-1).mean())
  top = top_of_neck + height * np.einsum("tij,j->ti", frame, local)
  skeleton = dataclasses.replace(
    sk,
    joint_names=(*sk.joint_names, HEAD_TOP_FROM_EYES),
    parents=(*sk.parents, head),
    twins=(*sk.twins, sk.num_joints),
    end_joints=(*sk.end_joints, sk.num_joints),
  )
  positions = np.concatenate([motion.positions, top[:, None].astype(np.float32)], axis=1)
  return motion.replace(positions=positions, skeleton=skeleton)


def _unit(v: np.ndarray) -> np.ndarray:
  return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _ancestors(parents, j: int) -> list[int]:
  out = []
  while parents[j] >= 0:
    j = parents[j]
    out.append(j)
  return out


def check_topology(motion: Motion, joints: dict) -> str | None:
  """Why ``joints`` (target -> source name) do not form the 16-joint chains, or None when they do."""
  motion = with_head_top(motion)
  tree = _Tree(motion)
  idx = {n: i for i, n in enumerate(tree.names)}
  j = {t: idx[s] for t, s in joints.items()}
  if len(set(j.values())) != len(j):
    same = [t for t in j if list(j.values()).count(j[t]) > 1]
    return f"{same[0]} and {same[1]} are the same joint ({joints[same[0]]})"
  for parent, child in MPII16.bones:
    a, b = TARGETS[parent], TARGETS[child]
    if j[a] not in tree.ancestors(j[b]):
      return f"{a} ({joints[a]}) is not above {b} ({joints[b]}) in the hierarchy"
  above = {j["pelvis"], *tree.ancestors(j["pelvis"])}
  legs = [set(tree.ancestors(j[f"{s}_foot"])) - above for s in ("left", "right")]
  if legs[0] & legs[1]:
    return "the two legs share joints below the pelvis"
  return None


def find_mapping(motion: Motion, joint_map=None) -> Mapping:
  """How ``motion``'s skeleton maps onto the 16-joint layout (see the module docstring).

  Raises:
    UserError: naming the joints that could not be placed and the file's own joint names.
  """
  motion = with_head_top(motion)
  names = motion.skeleton.joint_names
  where = motion.source or motion.name
  if joint_map is not None:
    given = read_joint_map(joint_map)
    missing = [t for t in TARGETS if t not in given]
    absent = [f"{t}={s}" for t, s in given.items() if s not in names]
    if missing or absent:
      what = f"not placed: {', '.join(missing)}" if missing else f"no such joint in the file: {', '.join(absent)}"
      raise UserError(f"{joint_map}: {what} ({where} has: {', '.join(names)})")
    joints = {t: given[t] for t in TARGETS}
    return _checked(motion, Mapping(f"file:{joint_map}", joints), where)
  for family, joints in FAMILIES.items():
    if set(joints.values()) <= set(names):
      return _checked(motion, Mapping(family, {t: joints[t] for t in TARGETS}), where)
  if motion.skeleton.bones:
    tree = _Tree(motion)
    for method, found in (("names", lambda: _by_names(tree)), ("topology", lambda: _by_topology(tree, motion.up_axis))):
      joints = found()
      if joints is not None and check_topology(motion, joints) is None:
        return Mapping(method, joints)
  raise UserError(
    f"{where}: could not place the 16 training joints on skeleton {motion.skeleton.name!r} "
    f"({len(names)} joints: {', '.join(names[:40])}{' ...' if len(names) > 40 else ''}); "
    'write a joint map (data.joint_map / --joint-map, one `target = "joint"` line per target: '
    f"{', '.join(TARGETS)})"
  )


def _checked(motion: Motion, mapping: Mapping, where: str) -> Mapping:
  why = check_topology(motion, mapping.joints)
  if why is not None:
    raise UserError(f"{where}: joint mapping {mapping.method}: {why}")
  return mapping


def leg_length(positions_TxJx3) -> float:
  """Mean leg length (hip -> knee -> ankle, mean over frames and both sides) of 16-joint positions."""
  p, j = np.asarray(positions_TxJx3, np.float64), TARGETS.index
  bone = lambda a, b: np.linalg.norm(p[:, j(a)] - p[:, j(b)], axis=-1).mean()
  return sum(bone(f"{s}_hip", f"{s}_knee") + bone(f"{s}_knee", f"{s}_foot") for s in ("left", "right")) / 2


def map_takes(motions, joint_map=None) -> tuple[list[Motion], dict]:
  """Every take on the 16-joint layout, and ``{take name: Mapping}``.

  One mapping per rig (takes whose joints are the same but for End Sites), decided on the joints all
  its takes have and checked on each, so that a dataset never mixes two readings of one rig (a Bandai
  take whose head End Site has a length beside one whose has none).
  """
  rigs: dict[tuple, list[Motion]] = {}
  for m in motions:
    if m.skeleton.joint_names != MPII16.joint_names:
      rigs.setdefault(tuple(n for n in m.skeleton.joint_names if not split_name(n)[2]), []).append(m)
  decided = {}  # by id(): takes of one name may come from two files (131_01.amc beside 131_01.bvh)
  for takes in rigs.values():
    common = set.intersection(*(set(t.skeleton.joint_names) for t in takes))
    mapping = find_mapping(_restrict(takes[0], common), joint_map)
    for t in takes:
      decided[id(t)] = mapping if t is takes[0] else _checked(t, mapping, t.source or t.name)
  out = [apply_mapping(m, decided[id(m)]) if id(m) in decided else m for m in motions]
  return out, {m.name: decided[id(m)] for m in motions if id(m) in decided}


def _restrict(motion: Motion, names: set) -> Motion:
  """``motion`` with only the joints named in ``names`` (its leaves may go; a joint whose parent goes
  stays, and then nothing is dropped)."""
  sk = motion.skeleton
  keep = [k for k, n in enumerate(sk.joint_names) if n in names]
  if len(keep) == sk.num_joints or any(sk.parents[k] >= 0 and sk.parents[k] not in keep for k in keep):
    return motion
  new = {k: i for i, k in enumerate(keep)}
  skeleton = dataclasses.replace(
    sk,
    joint_names=tuple(sk.joint_names[k] for k in keep),
    parents=tuple(-1 if sk.parents[k] < 0 else new[sk.parents[k]] for k in keep),
    twins=tuple(new.get(sk.twins[k], new[k]) for k in keep),
    end_joints=tuple(new[k] for k in sk.end_joints if k in new),
    feet=tuple(new[k] for k in sk.feet if k in new),
  )
  return motion.replace(positions=motion.positions[:, keep], skeleton=skeleton)


def to_mpii16(motion: Motion, joint_map=None) -> Motion:
  """``motion`` on the 16-joint training layout (unchanged when it is already on it)."""
  if motion.skeleton.joint_names == MPII16.joint_names:
    return motion
  return apply_mapping(motion, find_mapping(motion, joint_map))


def apply_mapping(motion: Motion, mapping: Mapping) -> Motion:
  if HEAD_TOP_FROM_EYES in mapping.joints.values():
    motion = with_head_top(motion)
  index = {n: i for i, n in enumerate(motion.skeleton.joint_names)}
  cols = [index[mapping.joints[n]] for n in TARGETS]
  return motion.replace(positions=motion.positions[:, cols], skeleton=MPII16)
