"""C3D marker files through ezc3d (the optional ``c3d`` extra): marker positions, rate and units.

Markers have no bones: every marker is a root of its own. A file whose header declares more frames
than it holds (a truncated recording) is refused with a one-line error, never read as a silent partial.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from chorjax.data.motion import Motion, Skeleton
from chorjax.errors import UserError, check_array, check_rate


def read_c3d(path, *, up_axis: str = "z") -> Motion:
  """Reads C3D markers as a Motion (joints = markers, in the file's units; C3D is usually z-up)."""
  path = Path(path)
  try:
    import ezc3d
  except ImportError:
    raise UserError(f"{path}: reading C3D needs ezc3d: pip install 'chorjax[c3d]'") from None
  if not path.is_file():
    raise UserError(f"{path}: no such file")
  head = path.read_bytes()[:512]
  if len(head) < 512 or head[1] != 0x50:
    raise UserError(f"{path}: not a C3D file (bad header)")
  first, last = struct.unpack("<2H", head[6:10])
  try:
    c = ezc3d.c3d(str(path))
  except Exception as e:  # ezc3d raises plain RuntimeError/IOError on malformed files
    raise UserError(f"{path}: unreadable C3D ({str(e).splitlines()[0][:120]})") from None
  pts = np.asarray(c["data"]["points"])  # [4, M, T]
  declared, held = last - first + 1, pts.shape[2]
  if declared != held:
    raise UserError(
      f"{path}: header declares {declared} frames ({first}..{last}) but the file holds {held}: "
      "truncated or inconsistent; refusing a partial read"
    )
  point = c["parameters"]["POINT"]
  rate = check_rate(np.asarray(point["RATE"]["value"]).ravel()[0], f"{path}: POINT:RATE")
  units = point["UNITS"]["value"][0] if point.get("UNITS", {}).get("value") else "mm"
  labels = [str(l).strip() or f"marker{i}" for i, l in enumerate(point["LABELS"]["value"])][: pts.shape[1]]
  labels = [l if labels.count(l) == 1 else f"{l}_{i}" for i, l in enumerate(labels)]
  if not pts.shape[1] or not held:
    raise UserError(f"{path}: {pts.shape[1]} markers x {held} frames: nothing to read")
  pos = np.transpose(pts[:3], (2, 1, 0)).astype(np.float32)  # [T, M, 3]
  missing = np.asarray(~np.isfinite(pos).all(axis=-1))
  never = [labels[j] for j in np.flatnonzero(np.all(missing, axis=0))]
  if never:
    raise UserError(f"{path}: marker {never[0]!r} is never seen ({len(never)} such markers): no position to fill with")
  check_array(np.where(missing[..., None], 0.0, pos), f"{path}: markers")
  if missing.any():  # occluded markers: hold the last seen position (and report it)
    pos = _fill_gaps(pos, missing)
  m = len(labels)
  skeleton = Skeleton(name=f"{path.stem}-markers", joint_names=tuple(labels), parents=(-1,) * m, twins=tuple(range(m)))
  return Motion(pos, fps=rate, skeleton=skeleton, up_axis=up_axis, units=units, name=path.stem, source=str(path))


def _fill_gaps(pos, missing):
  out = pos.copy()
  for j in range(pos.shape[1]):
    seen = np.flatnonzero(~missing[:, j])  # never empty: read_c3d refuses a marker that is never seen
    idx = np.maximum.accumulate(np.where(~missing[:, j], np.arange(len(pos)), 0))
    idx[: seen[0]] = seen[0]
    out[:, j] = pos[idx, j]
  return out
