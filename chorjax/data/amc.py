"""Acclaim ASF/AMC (the CMU database's native format): skeleton + frames -> joint positions.

The ASF gives units, the root's channel order and axis, and per bone its direction (world frame at
rest), length, axis (the bone's local frame as Euler angles and their order), degrees of freedom and
limits; comments and unknown keywords (e.g. ``:namespace``) are skipped. An AMC gives, per frame, the
root's translation and rotation and each bone's dof values. Forward kinematics, per bone with
``C`` = its axis rotation and ``M`` = its dof rotation::

    L_bone = L_parent @ C @ M @ C^-1        end = start + length * L_bone @ direction

Euler angles apply in the listed order about fixed axes ("XYZ": x first, then y, then z). Joints are
the root and the END of every bone, named after the bone. Positions are in ASF units unless
``scale`` is given (``asf_metres_scale`` converts to metres: 1 unit = 1/length inches).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from chorjax.data.bvh import _guess_feet, _guess_twins
from chorjax.data.motion import Motion, Skeleton
from chorjax.data.rotations import euler_to_matrix
from chorjax.errors import UserError, parse_numbers, read_text


class Asf:
  def __init__(self, path):
    self.path = Path(path)
    self.length_unit, self.degrees = 1.0, True
    self.root_order, self.root_axis = ["tx", "ty", "tz", "rx", "ry", "rz"], "xyz"
    self.root_position, self.root_orientation = np.zeros(3), np.zeros(3)
    self.bones: dict[str, dict] = {}
    self.parent: dict[str, str] = {}


def _fixed_axes_matrix(angles, order: str, degrees: bool):
  """Rotations about fixed axes applied in ``order`` (e.g. 'xyz': R = Rz Ry Rx)."""
  a = np.asarray(angles, np.float64)
  a = a if degrees else np.rad2deg(a)
  return euler_to_matrix(a[..., ::-1], order[::-1])


_ROOT_CHANNELS = ("tx", "ty", "tz", "rx", "ry", "rz")
_DOF = (*_ROOT_CHANNELS, "l")


def _channels(names: list[str], known, where: str) -> list[str]:
  """``names`` if every one is a known channel and none repeats, else a one-line error."""
  if any(n not in known for n in names) or len(set(names)) != len(names):
    raise UserError(f"{where} {' '.join(names)[:60]!r}: unknown or repeated channel (known: {' '.join(known)})")
  return names


def _three(words: list[str], where: str) -> np.ndarray:
  """The three numbers after a keyword (``direction 0 1 0``), else a one-line error."""
  if len(words) < 4:
    raise UserError(f"{where}: {words[0]} needs three numbers, found {len(words) - 1}")
  return np.array(parse_numbers(words[1:4], where))


def _axis_order(word: str, where: str) -> str:
  """An Euler axis order such as ``XYZ``: each of x, y, z once."""
  if sorted(word.lower()) != ["x", "y", "z"]:
    raise UserError(f"{where}: axis order {word[:20]!r} is not an order of x, y, z")
  return word.lower()


def read_asf(path) -> Asf:
  path = Path(path)
  lines = read_text(path, "ASF", errors="replace").splitlines()
  asf, section, bone = Asf(path), None, None
  for lineno, raw in enumerate(lines, start=1):
    line = raw.split("#")[0].strip()
    if not line:
      continue
    words = line.split()
    try:
      if words[0].startswith(":"):
        section = words[0][1:].lower()
        if section == "units" and len(words) > 1:  # units may also sit on the same line
          words = words[1:]
        else:
          continue
      if section == "units":
        if words[0] == "length":
          asf.length_unit = parse_numbers(words[1:2], f"{path}:{lineno}")[0]
          if not asf.length_unit > 0:
            raise UserError(f"{path}:{lineno}: length unit {asf.length_unit:g}: must be above 0")
        elif words[0] == "angle":
          if not words[1].lower().startswith(("deg", "rad")):
            raise UserError(f"{path}:{lineno}: angle unit {words[1][:20]!r}: only deg or rad are known")
          asf.degrees = words[1].lower().startswith("deg")
      elif section == "root":
        if words[0] == "order":
          asf.root_order = _channels([w.lower() for w in words[1:]], _ROOT_CHANNELS, f"{path}:{lineno}: root order")
        elif words[0] == "axis":
          asf.root_axis = _axis_order(words[1], f"{path}:{lineno}")
        elif words[0] == "position":
          asf.root_position = _three(words, f"{path}:{lineno}")
        elif words[0] == "orientation":
          asf.root_orientation = _three(words, f"{path}:{lineno}")
      elif section == "bonedata":
        if words[0] == "begin":
          bone = {"dof": [], "axis": np.zeros(3), "axis_order": "xyz", "line": lineno}
        elif words[0] == "end":
          if bone is None or "name" not in bone:
            raise UserError(f"{path}:{lineno}: bone block without a name")
          if bone["name"] in asf.bones or bone["name"] == "root":
            raise UserError(f"{path}:{bone['line']}: bone name {bone['name']!r} is used twice")
          asf.bones[bone["name"]] = bone
          bone = None
        elif bone is not None and words[0] == "name":
          bone["name"] = words[1]
        elif bone is not None and words[0] == "direction":
          bone["direction"] = _three(words, f"{path}:{lineno}")
        elif bone is not None and words[0] == "length":
          bone["length"] = parse_numbers(words[1:2], f"{path}:{lineno}")[0]
          if bone["length"] < 0:
            raise UserError(f"{path}:{lineno}: bone length {bone['length']:g} is negative")
        elif bone is not None and words[0] == "axis":
          bone["axis"] = _three(words, f"{path}:{lineno}")
          bone["axis_order"] = _axis_order(words[4], f"{path}:{lineno}") if len(words) > 4 else "xyz"
        elif bone is not None and words[0] == "dof":
          bone["dof"] = _channels([w.lower() for w in words[1:]], _DOF, f"{path}:{lineno}: dof")
      elif section == "hierarchy":
        if words[0] in ("begin", "end"):
          continue
        for child in words[1:]:
          if child in asf.parent and asf.parent[child] != words[0]:  # a tree: one parent a bone
            raise UserError(
              f"{path}:{lineno}: bone {child[:40]!r} is a child of {asf.parent[child][:40]!r} already (:hierarchy)"
            )
          asf.parent[child] = words[0]
    except (ValueError, IndexError):
      raise UserError(f"{path}:{lineno}: malformed {words[0]!r} line") from None
  _check_bones(asf, path)
  return asf


def _check_bones(asf: Asf, path: Path) -> None:
  """Every bone has a direction (not zero) and a length and a place in the hierarchy, the hierarchy names only
  bones the file defines, and there is at least one."""
  for name, b in asf.bones.items():
    if "direction" not in b or "length" not in b:
      raise UserError(f"{path}:{b['line']}: bone {name!r} lacks a direction or length")
    if not np.linalg.norm(b["direction"]) > 0:
      raise UserError(f"{path}:{b['line']}: bone {name!r} has a zero direction (it points nowhere)")
    if name not in asf.parent:
      raise UserError(f"{path}: bone {name!r} is missing from :hierarchy")
  for child, parent in asf.parent.items():
    for bone in (child, parent):
      if bone != "root" and bone not in asf.bones:
        raise UserError(f"{path}: :hierarchy names bone {bone[:40]!r}, which :bonedata does not define")
  if not asf.bones:
    raise UserError(f"{path}: no :bonedata")


def asf_metres_scale(asf: Asf) -> float:
  """Multiplier from ASF length units to metres (CMU: length 0.45 -> 1 unit = 1/0.45 inch)."""
  return 0.0254 / asf.length_unit


def find_asf(amc: Path) -> Path:
  """The only .asf in the AMC's folder, else the .asf whose name is the longest prefix of the AMC's."""
  candidates = sorted(amc.parent.glob("*.asf")) + sorted(amc.parent.glob("*.ASF"))
  if len(candidates) == 1:
    return candidates[0]
  prefixed = [c for c in candidates if amc.stem.startswith(c.stem)]
  if prefixed:
    return max(prefixed, key=lambda c: len(c.stem))
  raise UserError(f"{amc}: cannot tell which .asf belongs to it ({len(candidates)} in the folder); pass --asf PATH")


def read_amc(path, asf_path=None, *, fps: float = 120.0, scale: float = 1.0, units: str = "asf") -> Motion:
  """Reads an AMC with its ASF skeleton into joint positions (root + every bone's end)."""
  path = Path(path)
  asf = read_asf(asf_path or find_asf(path))
  lines = read_text(path, "AMC", errors="replace").splitlines()
  frames, starts, current, number = [], [], None, 0
  for lineno, raw in enumerate(lines, start=1):
    line = raw.strip()
    if not line or line.startswith("#") or line.startswith(":"):
      continue
    words = line.split()
    if len(words) == 1 and words[0].isascii() and words[0].isdigit():
      if len(words[0].lstrip("0")) > 12:  # more frames than any take: Python refuses 4,300 digits and more
        raise UserError(f"{path}:{lineno}: frame number {words[0][:20]}... has {len(words[0])} digits")
      if starts and int(words[0]) != number + 1:
        raise UserError(f"{path}:{lineno}: frame {words[0]} follows frame {number} (AMC frames count up by one)")
      number = int(words[0])
      current = {}
      frames.append(current)
      starts.append(lineno)
      continue
    if current is None:
      raise UserError(f"{path}:{lineno}: bone values before the first frame number")
    name = words[0]
    if name != "root" and name not in asf.bones:
      raise UserError(f"{path}:{lineno}: bone {name!r} is not in the skeleton {asf.path.name}")
    want = len(asf.root_order) if name == "root" else len(asf.bones[name]["dof"])
    values = parse_numbers(words[1:], f"{path}:{lineno}")
    if len(values) != want:
      raise UserError(f"{path}:{lineno}: {name} has {len(values)} values, its dof list has {want}")
    if name in current:
      raise UserError(f"{path}:{lineno}: {name} appears twice in one frame")
    current[name] = values
  if not frames:
    raise UserError(f"{path}: no frames")
  for frame, line in zip(frames, starts):  # a cut-off file ends in a frame that lacks bones: never filled with 0
    if frame.keys() != frames[0].keys():
      missing = sorted(set(frames[0]) - set(frame)) or sorted(set(frame) - set(frames[0]))
      raise UserError(
        f"{path}:{line}: this frame lists {len(frame)} bones, the first frame {len(frames[0])} "
        f"(differs in {missing[0]!r}; a truncated file?)"
      )
  pos, names, parents = _fk(asf, frames, path)
  skeleton = Skeleton(
    name=asf.path.stem,
    joint_names=names,
    parents=parents,
    twins=_guess_twins(names),
    end_joints=tuple(i for i, n in enumerate(names) if n not in asf.parent.values()),
    feet=_guess_feet(names),
  )
  return Motion(
    (pos * scale).astype(np.float32),
    fps=fps,
    skeleton=skeleton,
    up_axis="y",
    units=units,
    name=path.stem,
    source=str(path),
  )


def _fk(asf: Asf, frames, path):
  t = len(frames)
  names = ["root"] + list(asf.bones)
  index = {n: i for i, n in enumerate(names)}
  order = _topological(asf, names)
  parents = tuple(-1 if n == "root" else index[asf.parent[n]] for n in names)
  pos = np.zeros((t, len(names), 3))
  glob = np.zeros((t, len(names), 3, 3))

  def column(name, dofs):
    vals = np.zeros((t, len(dofs)))
    for f, fr in enumerate(frames):
      if name in fr:
        vals[f] = fr[name]
    return vals

  def rotation_of(vals_TxN, channels):
    """The rotation of a frame's rx/ry/rz values, applied in the listed order (identity if none)."""
    rot = [(k, ch[1]) for k, ch in enumerate(channels) if ch in ("rx", "ry", "rz")]
    if not rot:
      return np.broadcast_to(np.eye(3), (t, 3, 3))
    return _fixed_axes_matrix(vals_TxN[:, [k for k, _ in rot]], "".join(a for _, a in rot), asf.degrees)

  root_vals = column("root", asf.root_order)
  trans = np.zeros((t, 3))
  for k, ch in enumerate(asf.root_order):
    if ch in ("tx", "ty", "tz"):
      trans[:, "xyz".index(ch[1])] = root_vals[:, k]
  c_root = _fixed_axes_matrix(asf.root_orientation, asf.root_axis, asf.degrees)
  m_root = rotation_of(root_vals, asf.root_order)
  pos[:, 0] = asf.root_position + trans
  glob[:, 0] = c_root @ m_root @ c_root.T
  for name in order:
    b, i, p = asf.bones[name], index[name], index[asf.parent[name]]
    c = _fixed_axes_matrix(b["axis"], b["axis_order"], asf.degrees)
    m = rotation_of(column(name, b["dof"]), b["dof"])
    glob[:, i] = glob[:, p] @ c @ m @ c.T
    pos[:, i] = pos[:, p] + b["length"] * np.einsum("tij,j->ti", glob[:, i], b["direction"])
  return pos, tuple(names), parents


def _topological(asf: Asf, names):
  out, done = [], {"root"}
  pending = [n for n in names if n != "root"]
  while pending:
    ready = [n for n in pending if asf.parent[n] in done]
    if not ready:
      raise UserError(f"{asf.path}: :hierarchy has a cycle or names an unknown bone ({pending[0]!r})")
    for n in ready:
      out.append(n)
      done.add(n)
    pending = [n for n in pending if n not in done]
  return out
