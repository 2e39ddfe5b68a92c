"""C3D marker files through ezc3d (the optional ``c3d`` extra): marker positions, rate and units.

Markers have no bones: every marker is a root of its own. A file whose header declares more frames
than it holds (a truncated recording) is refused with a one-line error, never read as a silent partial.

ezc3d is native code that trusts the file: one damaged byte in a parameter block can crash the process
(found by tests/test_fuzz.py). So it runs in a child process with a memory ceiling; a crash, a timeout
or an allocation beyond the ceiling is a one-line error naming the file, never the end of the caller.
"""

from __future__ import annotations

import importlib.util
import json
import os
import struct
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from chorjax.data.motion import Motion, Skeleton
from chorjax.errors import UserError, check_array, check_rate


def read_c3d(path, *, up_axis: str = "z") -> Motion:
  """Reads C3D markers as a Motion (joints = markers, in the file's units; C3D is usually z-up)."""
  path = Path(path)
  if importlib.util.find_spec("ezc3d") is None:
    raise UserError(f"{path}: reading C3D needs ezc3d: pip install 'chorjax[c3d]'") from None
  if not path.is_file():
    raise UserError(f"{path}: no such file")
  head = path.read_bytes()[:512]
  if len(head) < 512 or head[1] != 0x50:
    raise UserError(f"{path}: not a C3D file (bad header)")
  first, last = struct.unpack("<2H", head[6:10])
  pts, rate, units, labels = _read_isolated(path)
  declared, held = last - first + 1, pts.shape[2]
  if declared != held:
    raise UserError(
      f"{path}: header declares {declared} frames ({first}..{last}) but the file holds {held}: "
      "truncated or inconsistent; refusing a partial read"
    )
  rate = check_rate(rate, f"{path}: POINT:RATE")
  labels = [str(l).strip() or f"marker{i}" for i, l in enumerate(labels)][: pts.shape[1]]
  labels += [f"marker{i}" for i in range(len(labels), pts.shape[1])]
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


_CHILD = """
import json, resource, sys
import numpy as np
import ezc3d
soft, hard = resource.getrlimit(resource.RLIMIT_AS)  # a limit the process already runs under stays the bound
ceiling = int(sys.argv[3]) if hard == resource.RLIM_INFINITY else min(int(sys.argv[3]), hard)
resource.setrlimit(resource.RLIMIT_AS, (ceiling, hard))
try:
  c = ezc3d.c3d(sys.argv[1])
  point = c["parameters"]["POINT"]
  rate = float(np.asarray(point["RATE"]["value"], np.float64).ravel()[0])
  units = str(point["UNITS"]["value"][0]) if point.get("UNITS", {}).get("value") else "mm"
  labels = [str(l) for l in point.get("LABELS", {}).get("value", [])]
  np.save(sys.argv[2], np.asarray(c["data"]["points"], np.float64))
  print(json.dumps({"rate": rate, "units": units, "labels": labels}))
except Exception as e:
  print(json.dumps({"error": (str(e).splitlines() or [type(e).__name__])[0][:120]}))
"""
# seconds the child may take: ezc3d reads a sound file at ~50 MB/s here, a damaged one can spin for minutes
TIMEOUT_BASE_S, TIMEOUT_PER_MB_S = 20, 2


def _memory_ceiling() -> int:
  """Bytes the child may map: half this machine's memory (ezc3d allocates what a header claims)."""
  try:
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2
  except (ValueError, OSError):
    return 8 << 30


def _read_isolated(path: Path):
  """``(points [4, M, T], rate, units, labels)`` read by ezc3d in a child process (module docstring)."""
  timeout = TIMEOUT_BASE_S + TIMEOUT_PER_MB_S * path.stat().st_size / 2**20
  with tempfile.TemporaryDirectory(prefix="chorjax-c3d-") as tmp:
    out = Path(tmp) / "points.npy"
    try:
      done = subprocess.run(
        [sys.executable, "-I", "-c", _CHILD, str(path), str(out), str(_memory_ceiling())],
        capture_output=True,
        text=True,
        timeout=timeout,
      )
    except subprocess.TimeoutExpired:
      raise UserError(f"{path}: the C3D reader (ezc3d) took over {timeout:.0f} s: a damaged file?") from None
    try:
      said = json.loads(done.stdout.strip().splitlines()[-1]) if done.returncode == 0 else {}
    except (ValueError, IndexError):
      said = {}
    if "error" in said:
      raise UserError(f"{path}: unreadable C3D ({said['error']})")
    if done.returncode != 0 or not out.is_file():
      why = f"signal {-done.returncode}" if done.returncode < 0 else f"exit {done.returncode}"
      raise UserError(f"{path}: the C3D reader (ezc3d) failed on it ({why}): a damaged or oversized file")
    points = np.load(out)
  if points.ndim != 3 or points.shape[0] < 3:
    raise UserError(f"{path}: unreadable C3D (points {points.shape})")
  return points, said["rate"], said["units"], said["labels"]


def _fill_gaps(pos, missing):
  out = pos.copy()
  for j in range(pos.shape[1]):
    seen = np.flatnonzero(~missing[:, j])  # never empty: read_c3d refuses a marker that is never seen
    idx = np.maximum.accumulate(np.where(~missing[:, j], np.arange(len(pos)), 0))
    idx[: seen[0]] = seen[0]
    out[:, j] = pos[idx, j]
  return out
