"""``.npz`` samples: positions ``[K, T, J, 3]`` with fps, skeleton, axes and the sampling settings."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from chorjax.data.motion import Motion, Skeleton
from chorjax.errors import UserError, atomic_write


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


def read_npz(path) -> list[Motion]:
  path = Path(path)
  try:
    with np.load(path, allow_pickle=False) as z:
      pos, meta = z["positions"], json.loads(str(z["meta"]))
  except FileNotFoundError:
    raise UserError(f"{path}: no such file") from None
  except (KeyError, ValueError, OSError, zipfile.BadZipFile, json.JSONDecodeError) as e:
    raise UserError(f"{path}: not a chorjax sample .npz ({type(e).__name__})") from None
  if pos.ndim == 3:
    pos = pos[None]
  sk = Skeleton.from_dict(meta["skeleton"])
  return [
    Motion(
      p,
      meta["fps"],
      sk,
      meta["up_axis"],
      meta["units"],
      name=f"{path.stem}#{k}" if len(pos) > 1 else path.stem,
      source=str(path),
    )
    for k, p in enumerate(pos)
  ]
