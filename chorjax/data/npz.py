"""``.npz`` samples: positions ``[K, T, J, 3]`` with fps, skeleton, axes and the sampling settings."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from chorjax.data.motion import Motion, Skeleton
from chorjax.errors import UserError, atomic_write, check_array, check_rate, check_up_axis, load_json


def write_npz(
  path,
  positions_KxTxJx3,
  *,
  fps: float,
  skeleton: Skeleton,
  up_axis: str,
  units: str,
  settings: dict,
  overwrite: bool = True,
) -> Path:
  pos = np.asarray(positions_KxTxJx3, np.float32)
  meta = {"fps": fps, "skeleton": skeleton.to_dict(), "up_axis": up_axis, "units": units, "settings": settings}

  def write(tmp):
    with open(tmp, "wb") as f:
      np.savez_compressed(f, positions=pos, meta=np.array(json.dumps(meta)))

  return atomic_write(path, write, overwrite=overwrite)


# Motion compresses 1-4x (a held pose far more): a member over 256 MiB that inflates by more than this is a zip
# bomb, not a take.
MAX_INFLATION, LARGE = 100, 256 << 20


def _check_claims(path: Path) -> None:
  """Refuses an ``.npz`` whose arrays' headers claim more bytes than their members hold, or that inflate by more
  than ``MAX_INFLATION`` (a header is never trusted for an allocation: numpy allocates what it says before
  reading a byte), and arrays of anything but real numbers."""
  with zipfile.ZipFile(path) as z:
    for info in z.infolist():
      if not info.filename.endswith(".npy"):
        continue
      with z.open(info) as f:
        version = np.lib.format.read_magic(f)
        read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        shape, _, dtype = read(f, max_header_size=10_000)
        claimed = int(np.prod(shape, dtype=object)) * dtype.itemsize
      if claimed > info.file_size:
        raise UserError(
          f"{path}: {info.filename} claims {claimed:,} bytes of data ({shape}), the file holds {info.file_size:,}"
        )
      if info.file_size > MAX_INFLATION * max(info.compress_size, 1) and info.file_size > LARGE:
        raise UserError(
          f"{path}: {info.filename} inflates from {info.compress_size:,} to {info.file_size:,} bytes "
          f"(over {MAX_INFLATION}x; motion compresses 1-4x)"
        )
      if info.filename == "positions.npy" and dtype.kind not in "fiu":
        raise UserError(f"{path}: positions are {dtype} values, not real numbers")


def read_npz(path) -> list[Motion]:
  path = Path(path)
  try:
    _check_claims(path)
    with np.load(path, allow_pickle=False) as z:
      pos, meta = z["positions"], load_json(str(z["meta"]))
  except FileNotFoundError:
    raise UserError(f"{path}: no such file") from None
  except (KeyError, ValueError, OSError, EOFError, zipfile.BadZipFile, json.JSONDecodeError) as e:
    raise UserError(f"{path}: not a chorjax sample .npz ({type(e).__name__})") from None
  try:
    sk = Skeleton.from_dict(meta["skeleton"])
    fps, up_axis, units = float(meta["fps"]), str(meta["up_axis"]), str(meta["units"])
  except (KeyError, TypeError, ValueError) as e:
    raise UserError(f"{path}: not a chorjax sample .npz (meta: {type(e).__name__} {str(e)[:60]})") from None
  if pos.ndim == 3:
    pos = pos[None]
  if pos.ndim != 4 or pos.shape[-2:] != (sk.num_joints, 3) or pos.shape[0] < 1 or pos.shape[1] < 1:
    raise UserError(
      f"{path}: positions {pos.shape}, expected [K >= 1, T >= 1, {sk.num_joints}, 3] for skeleton {sk.name}"
    )
  check_rate(fps, f"{path}: fps")
  check_up_axis(up_axis, f"{path}: meta")
  check_array(pos, f"{path}: positions")
  return [
    Motion(
      p,
      fps,
      sk,
      up_axis,
      units,
      name=f"{path.stem}#{k}" if len(pos) > 1 else path.stem,
      source=str(path),
    )
    for k, p in enumerate(pos)
  ]
