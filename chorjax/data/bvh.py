"""BVH motion files: any hierarchy in, joint positions by forward kinematics; positions -> BVH out by IK.

Reading: ROOT/JOINT/End Site, 3 or 6 channels on any joint, any Euler order per joint (mixed orders in
one file), CRLF/LF and tab separators. Position channels, where present, ARE the joint's translation
in its parent's frame (they replace the OFFSET, as Blender reads them). End Sites become joints named
``<parent>_end``, except those with a zero offset: they sit on their parent and say nothing (and a
file written here closes every leaf joint with one, so a round trip adds no joints). Positions stay in
the file's units.

Writing (``write_bvh``): for every joint with children, the rotation that takes its rest-pose bone
directions to the observed ones, composed down the chain. One child: the smallest rotation (swing)
relative to the parent's frame, so a bone never twists about itself (the twist choice). Several
children (pelvis, thorax): the best-fit rotation of all child directions (Kabsch). The rest pose is
the first frame. With ``exact=True`` (default) every joint also gets position channels holding its
real per-frame offset, so reading the file back gives the input positions exactly; with
``exact=False`` the skeleton is rigid (mean bone lengths), as most animation tools expect.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from chorjax.data.motion import Motion, Skeleton
from chorjax.data.rotations import euler_to_matrix, matrix_to_euler, pose_rotations
from chorjax.errors import UserError, atomic_write, check_rate, parse_numbers, read_text, whole_number

_ROT = {"xrotation": "x", "yrotation": "y", "zrotation": "z"}
_POS = {"xposition": 0, "yposition": 1, "zposition": 2}


class _Joint:
  def __init__(self, name, parent, line):
    self.name, self.parent, self.line = name, parent, line
    self.offset = np.zeros(3)
    self.channels: list[str] = []
    self.end = False


def _tokens(path: Path, text: str):
  for lineno, line in enumerate(text.splitlines(), start=1):
    for tok in line.split():
      yield lineno, tok


def _parse_hierarchy(path: Path, text: str):
  toks = list(_tokens(path, re.split(r"^[ \t]*MOTION[ \t]*\r?$", text, maxsplit=1, flags=re.M)[0]))
  joints, stack, i = [], [], 0

  def need(k):
    if i + k > len(toks):
      last = toks[-1][0] if toks else 1
      raise UserError(f"{path}:{last}: truncated HIERARCHY (unexpected end of file)")

  need(1)
  if toks[0][1].upper() != "HIERARCHY":
    raise UserError(f"{path}:{toks[0][0]}: expected HIERARCHY, found {toks[0][1][:30]!r}")
  i = 1
  while i < len(toks):
    line, tok = toks[i]
    up = tok.upper()
    if up in ("ROOT", "JOINT") or (up == "END" and i + 1 < len(toks) and toks[i + 1][1].upper() == "SITE"):
      if up == "END":
        parent = stack[-1] if stack else None
        if parent is None:
          raise UserError(f"{path}:{line}: End Site outside a joint")
        j = _Joint(f"{joints[parent].name}_end", parent, line)
        j.end = True
        i += 2
      else:
        need(2)
        if (up == "JOINT") != bool(stack):
          where = "outside the ROOT's braces" if stack == [] else "inside another joint (one ROOT per file)"
          raise UserError(f"{path}:{line}: {tok} {where}")
        j = _Joint(toks[i + 1][1], stack[-1] if stack else None, line)
        i += 2
      joints.append(j)
      need(1)
      if toks[i][1] != "{":
        raise UserError(f"{path}:{toks[i][0]}: expected '{{' after {j.name}")
      stack.append(len(joints) - 1)
      i += 1
    elif up in ("OFFSET", "CHANNELS") and not stack:
      raise UserError(f"{path}:{line}: {tok} outside a joint")
    elif up == "OFFSET":
      need(4)
      joints[stack[-1]].offset = np.array(parse_numbers([t for _, t in toks[i + 1 : i + 4]], f"{path}:{line}: OFFSET"))
      i += 4
    elif up == "CHANNELS":
      need(2)
      i = _read_channels(path, toks, i, joints[stack[-1]])
    elif tok == "}":
      if not stack:
        raise UserError(f"{path}:{line}: unbalanced '}}'")
      stack.pop()
      i += 1
      if not stack:
        break
    else:
      raise UserError(f"{path}:{line}: unexpected {tok[:30]!r} in HIERARCHY")
  if stack or not joints:
    raise UserError(f"{path}:{toks[-1][0]}: truncated HIERARCHY (unclosed braces)")
  _check_names(path, joints, toks, i)
  return joints


def _read_channels(path: Path, toks, i: int, joint: _Joint) -> int:
  """Reads ``CHANNELS n name...`` at token ``i`` into ``joint``; returns the next token's index."""
  line = toks[i][0]
  try:
    n = whole_number(toks[i + 1][1])
  except ValueError:
    raise UserError(f"{path}:{line}: CHANNELS needs a count") from None
  if i + 2 + n > len(toks):
    raise UserError(f"{path}:{toks[-1][0]}: truncated HIERARCHY (unexpected end of file)")
  names = [t.lower() for _, t in toks[i + 2 : i + 2 + n]]
  bad = [c for c in names if c not in _ROT and c not in _POS]
  if bad or n not in (3, 6) or len(set(names)) != n:
    raise UserError(
      f"{path}:{line}: channel-count mismatch, unknown or repeated channel ({n} declared: {' '.join(names)[:60]})"
    )
  if joint.channels:
    raise UserError(f"{path}:{line}: a second CHANNELS line for {joint.name}")
  joint.channels = names
  return i + 2 + n


def _check_names(path: Path, joints, toks, i: int) -> None:
  """Nothing after the ROOT's closing brace (a second ROOT, a stray brace, junk: one skeleton, closed once)
  and no joint name twice (retargeting and mapping go by name)."""
  if i < len(toks):
    raise UserError(f"{path}:{toks[i][0]}: unexpected {toks[i][1][:30]!r} after the ROOT's closing brace")
  seen: dict[str, int] = {}
  for j in joints:
    if j.name in seen:
      raise UserError(f"{path}:{j.line}: joint name {j.name!r} is used twice (first on line {seen[j.name]})")
    seen[j.name] = j.line


def _parse_motion(path: Path, text: str, num_channels: int):
  lines = text.splitlines()
  start = next((k for k, l in enumerate(lines) if l.strip().upper() == "MOTION"), None)
  if start is None:
    raise UserError(f"{path}: no MOTION section")
  try:
    frames = whole_number(lines[start + 1].split(":")[1])
    frame_time = parse_numbers([lines[start + 2].split(":")[1]], f"{path}:{start + 3}")[0]
    assert lines[start + 1].strip().lower().startswith("frames") and 0 < frame_time < 1e3
  except (IndexError, ValueError, AssertionError):
    raise UserError(f"{path}:{start + 2}: expected 'Frames: N' and 'Frame Time: T' after MOTION") from None
  if frames < 1:
    raise UserError(f"{path}:{start + 2}: 'Frames: {frames}': the MOTION section holds no frame (an empty clip)")
  rows = []
  for k in range(start + 3, len(lines)):
    if not lines[k].strip():
      continue
    cells = lines[k].split()
    if len(cells) != num_channels:
      raise UserError(f"{path}:{k + 1}: {len(cells)} values, the hierarchy declares {num_channels} channels")
    rows.append(parse_numbers(cells, f"{path}:{k + 1}"))
  if len(rows) != frames:
    raise UserError(f"{path}: header says {frames} frames, the file holds {len(rows)}")
  return np.asarray(rows, np.float64).reshape(frames, num_channels), frame_time


def read_bvh(
  path, *, drop_first_frame: bool = False, scale: float = 1.0, units: str = "file", up_axis: str = "y"
) -> Motion:
  """Reads a BVH file into joint positions (End Sites included).

  Args:
    path: the file.
    drop_first_frame: drop frame 0 (some converters prepend a T-pose frame).
    scale: multiplies every length (e.g. 0.01 for centimetres -> metres); recorded via ``units``.
    units: the unit name recorded in the Motion.
    up_axis: the file's up axis (BVH is normally y-up).
  """
  path = Path(path)
  text = read_text(path, "BVH", errors="replace")
  joints = _parse_hierarchy(path, text)
  num_channels = sum(len(j.channels) for j in joints)
  data, frame_time = _parse_motion(path, text, num_channels)
  if drop_first_frame:
    if len(data) < 2:
      raise UserError(f"{path}: one frame; dropping the first leaves nothing")
    data = data[1:]
  pos = forward_kinematics(joints, data) * scale
  keep = [k for k, j in enumerate(joints) if not (j.end and not np.any(j.offset))]
  new = {k: i for i, k in enumerate(keep)}
  joints, pos = [joints[k] for k in keep], pos[:, keep]
  names = tuple(j.name for j in joints)
  parents = tuple(-1 if j.parent is None else new[j.parent] for j in joints)
  skeleton = Skeleton(
    name=path.stem,
    joint_names=names,
    parents=parents,
    twins=_guess_twins(names),
    end_joints=tuple(k for k in range(len(joints)) if k not in parents),
    feet=_guess_feet(names),
  )
  fps = check_rate(1.0 / frame_time, f"{path}: Frame Time {frame_time:g}")
  fps = float(round(fps)) if abs(fps - round(fps)) < 0.01 else fps  # '.0083333' means 120 fps
  return Motion(
    pos.astype(np.float32), fps=fps, skeleton=skeleton, up_axis=up_axis, units=units, name=path.stem, source=str(path)
  )


def forward_kinematics(joints, data_TxC) -> np.ndarray:
  t = data_TxC.shape[0]
  pos = np.zeros((t, len(joints), 3))
  rot = np.zeros((t, len(joints), 3, 3))
  col = 0
  for k, j in enumerate(joints):
    chans = data_TxC[:, col : col + len(j.channels)]
    col += len(j.channels)
    local_t = np.broadcast_to(j.offset, (t, 3)).copy()
    p_idx = [(i, _POS[c]) for i, c in enumerate(j.channels) if c in _POS]
    if p_idx:
      for i, axis in p_idx:
        local_t[:, axis] = chans[:, i]
    r_idx = [(i, _ROT[c]) for i, c in enumerate(j.channels) if c in _ROT]
    local_r = (
      euler_to_matrix(chans[:, [i for i, _ in r_idx]], "".join(a for _, a in r_idx))
      if r_idx
      else np.broadcast_to(np.eye(3), (t, 3, 3))
    )
    if j.parent is None:
      pos[:, k], rot[:, k] = local_t, local_r
    else:
      pos[:, k] = pos[:, j.parent] + np.einsum("tij,tj->ti", rot[:, j.parent], local_t)
      rot[:, k] = rot[:, j.parent] @ local_r
  return pos


def _guess_twins(names) -> tuple[int, ...]:
  """Left/right twins by name (Left/Right prefixes, _L/_R suffixes, l/r prefixes of CMU names)."""
  index = {n: i for i, n in enumerate(names)}
  pairs = [("Left", "Right"), ("left", "right"), ("_L", "_R"), ("L", "R"), ("l", "r")]

  def twin(n):
    for a, b in pairs:
      for x, y in ((a, b), (b, a)):
        for cand in (
          n.replace(x, y, 1) if n.startswith(x) else None,
          n[: -len(x)] + y if n.endswith(x) else None,
          n.replace(x + "_", y + "_") if (x + "_") in n else None,
        ):
          if cand and cand != n and cand in index:
            return index[cand]
    return index[n]

  out = [twin(n) for n in names]
  return tuple(t if out[t] == i else i for i, t in enumerate(out))  # keep only symmetric pairs


def _guess_feet(names) -> tuple[int, ...]:
  keys = ("ankle", "foot")
  return tuple(i for i, n in enumerate(names) if any(k in n.lower() for k in keys) and "end" not in n.lower())[:2]


# ---------------------------------------------------------------- writing


def bvh_names(joint_names) -> list[str]:
  """Joint names a BVH can hold: one token each (whitespace and braces become ``_``), unique, not empty."""
  out: list[str] = []
  for name in joint_names:
    base = re.sub(r"[\s{}]+", "_", name) or "joint"
    token, k = base, 2
    while token in out:
      token, k = f"{base}_{k}", k + 1
    out.append(token)
  return out


def write_bvh(motion: Motion, path, *, exact: bool = True, order: str = "zyx", overwrite: bool = True) -> Path:
  """Writes joint positions as a BVH file by inverse kinematics (see the module docstring)."""
  pos = np.asarray(motion.positions, np.float64)
  sk = motion.skeleton
  t, j = pos.shape[:2]
  children = {k: [c for c in range(j) if sk.parents[c] == k] for k in range(j)}
  rest = pos[0]
  lengths = np.linalg.norm(pos - pos[:, np.maximum(np.array(sk.parents), 0)], axis=-1).mean(0)
  glob = pose_rotations(pos, sk.parents, sk.topological_order)
  axes = {"x": "X", "y": "Y", "z": "Z"}
  rot_names = " ".join(f"{axes[a]}rotation" for a in order)
  lines = ["HIERARCHY"]
  names = bvh_names(sk.joint_names)

  def offset_of(k):
    if sk.parents[k] < 0:
      return rest[k]
    d = rest[k] - rest[sk.parents[k]]
    return d if exact else d / max(np.linalg.norm(d), 1e-12) * lengths[k]

  with_channels = []  # MOTION columns follow the order channels are declared in
  todo = [(sk.root, 0, False)]  # (joint, depth, closing): a stack, not recursion (chains thousands deep)
  while todo:
    k, depth, closing = todo.pop()
    ind, leaf = "  " * depth, not children[k]
    if closing:
      if leaf:  # exact mode keeps leaves as joints (they carry positions); close with a zero End Site
        lines.extend([f"{ind}  End Site", f"{ind}  {{", f"{ind}    OFFSET 0 0 0", f"{ind}  }}"])
      lines.append(f"{ind}}}")
      continue
    if leaf and sk.parents[k] >= 0 and not exact:
      lines.extend([f"{ind}End Site", f"{ind}{{", f"{ind}  OFFSET {_fmt(offset_of(k))}", f"{ind}}}"])
      continue
    kind = "ROOT" if sk.parents[k] < 0 else "JOINT"
    with_channels.append(k)
    lines.extend([f"{ind}{kind} {names[k]}", f"{ind}{{", f"{ind}  OFFSET {_fmt(offset_of(k))}"])
    six = sk.parents[k] < 0 or exact
    lines.append(f"{ind}  CHANNELS {6 if six else 3} " + ("Xposition Yposition Zposition " if six else "") + rot_names)
    todo.append((k, depth, True))
    todo.extend((c, depth + 1, False) for c in reversed(children[k]))
  cols = []
  for k in with_channels:
    parent = sk.parents[k]
    parent_r = np.broadcast_to(np.eye(3), (t, 3, 3)) if parent < 0 else glob[:, parent]
    local_r = np.swapaxes(parent_r, -1, -2) @ glob[:, k]
    if parent < 0:
      cols.append(pos[:, k])
    elif exact:
      cols.append(np.einsum("tji,tj->ti", parent_r, pos[:, k] - pos[:, parent]))  # offset in parent frame
    cols.append(matrix_to_euler(local_r, order))
  table = np.concatenate(cols, axis=1)
  lines += ["MOTION", f"Frames: {t}", f"Frame Time: {1.0 / motion.fps:.8f}"]
  body = "\n".join(" ".join(f"{v:.6f}" for v in row) for row in table)
  text = "\n".join(lines) + "\n" + body + "\n"
  return atomic_write(path, lambda p: p.write_text(text), overwrite=overwrite)


def _fmt(v):
  return " ".join(f"{x:.6f}" for x in v)
