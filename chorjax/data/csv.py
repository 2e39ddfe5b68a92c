"""CSV motion files: one row per frame, ``3 * J`` comma-separated numbers ``x1,y1,z1,...``, no header.

This is the layout of the bundled CMU subject 94 takes (16 joints, 48 columns, y pointing down).
A CSV of any other skeleton carries a sidecar, ``<stem>.skeleton.json`` beside it (written by
``write_csv``): the joint tree, frame rate, up axis and units, which CSV cannot hold. When present,
it decides them; otherwise the caller's arguments (``data.skeleton``, ``data.fps``, ``data.up_axis``) do.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from chorjax.data.motion import Motion, Skeleton
from chorjax.data.skeletons import MPII16, read_sidecar
from chorjax.errors import UserError, atomic_write, parse_numbers, read_text


def read_csv(
  path, skeleton: Skeleton = MPII16, fps: float = 30.0, up_axis: str = "-y", units: str = "arbitrary"
) -> Motion:
  """Reads a CSV motion file.

  Args:
    path: the file.
    skeleton: the joint layout; the file must have ``3 * skeleton.num_joints`` columns.
    fps: the frame rate (CSV files do not record it).
    up_axis: the signed up axis of the file's coordinates (cmu94: ``-y``, y points down).
    units: the length unit.

  Returns:
    The Motion.

  Raises:
    UserError: naming the file and line, for an empty file, a wrong or ragged column count, a
      non-numeric cell, or a NaN/Inf value.
  """
  path = Path(path)
  if has_sidecar(path):
    skeleton, fps, up_axis, units = read_sidecar(sidecar_path(path))
  text = read_text(path, "CSV")
  want = 3 * skeleton.num_joints
  rows = []
  for lineno, line in enumerate(text.splitlines(), start=1):
    line = line.strip()
    if not line:
      continue
    cells = line.split(",")
    if len(cells) != want:
      raise UserError(
        f"{path}:{lineno}: expected {want} columns ({skeleton.num_joints} joints x 3 "
        f"for skeleton {skeleton.name}), found {len(cells)}"
      )
    rows.append(parse_numbers(cells, f"{path}:{lineno}", columns=True))
  if not rows:
    raise UserError(f"{path}: empty file (no frames)")
  positions = np.asarray(rows, dtype=np.float32).reshape(len(rows), skeleton.num_joints, 3)
  return Motion(positions, fps=fps, skeleton=skeleton, up_axis=up_axis, units=units, name=path.stem, source=str(path))


def sidecar_path(csv_path) -> Path:
  path = Path(csv_path)
  return path.with_name(path.stem + ".skeleton.json")


def has_sidecar(csv_path) -> bool:
  """Whether a sidecar lies beside ``csv_path`` (none can where its name would be longer than the file
  system allows: a CSV named with 250 characters)."""
  side = sidecar_path(csv_path)
  try:
    if side.is_file():
      return True
    if side.exists():  # a folder or a device where the sidecar would be
      raise UserError(f"{side}: not a file; a CSV's sidecar is the file NAME.skeleton.json beside it")
  except OSError:
    pass
  return False


def sidecars(skeleton, path) -> list[Path]:
  """The sidecar :func:`write_csv` puts beside the CSV ``path`` for a motion of ``skeleton``: one for any
  skeleton but the 16-joint one, none for that."""
  return [sidecar_path(path)] if skeleton.joint_names != MPII16.joint_names else []


def written_paths(motion_or_positions, path) -> list[Path]:
  """What :func:`write_csv` writes for it at ``path``: the CSV, and the sidecar beside it where it needs one."""
  m = motion_or_positions
  return [Path(path), *(sidecars(m.skeleton, path) if isinstance(m, Motion) else [])]


def write_csv(motion_or_positions, path, *, overwrite: bool = True) -> Path:
  """Writes ``[T, J, 3]`` positions (or a Motion) in the CSV layout, atomically; a Motion of any
  skeleton but the 16-joint one also gets its sidecar (see the module docstring)."""
  pos = getattr(motion_or_positions, "positions", motion_or_positions)
  pos = np.asarray(pos, dtype=np.float32)
  flat = pos.reshape(pos.shape[0], -1)
  m = motion_or_positions
  if len(written_paths(m, path)) > 1:
    assert isinstance(m, Motion)
    side = {"skeleton": m.skeleton.to_dict(), "fps": m.fps, "up_axis": m.up_axis, "units": m.units}
    atomic_write(sidecar_path(path), lambda tmp: tmp.write_text(json.dumps(side, indent=1)), overwrite=overwrite)
  return atomic_write(path, lambda tmp: np.savetxt(tmp, flat, delimiter=",", fmt="%.7g"), overwrite=overwrite)
