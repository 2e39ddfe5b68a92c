"""Static plots: trajectories of the pelvis and the end joints (needs the ``viz`` extra)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from chorjax.data.motion import Motion
from chorjax.errors import UserError, atomic_write


def require_matplotlib():
  try:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt
  except ImportError:
    raise UserError("this needs matplotlib: pip install 'chorjax[viz]'") from None


def save_figure(fig, path) -> Path:
  """Writes a matplotlib figure atomically (format from the suffix, PNG by default) and closes it."""
  import matplotlib.pyplot as plt

  fmt = (Path(path).suffix or ".png").lstrip(".")
  try:
    return atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=80, format=fmt))
  finally:
    plt.close(fig)


def plot_trajectories(motion: Motion, path, split: int = 200) -> Path:
  """Plots x, y, z of the pelvis and end joints over time: frames [0, split) and [split, T).

  As in the reference notebook: the first ``split`` frames in the top row, the rest below.
  """
  plt = require_matplotlib()
  sk = motion.skeleton
  joints = [sk.root] + [j for j in sk.end_joints if j != sk.root]
  pos = motion.positions
  parts = [(0, min(split, motion.num_frames)), (min(split, motion.num_frames), motion.num_frames)]
  parts = [p for p in parts if p[1] > p[0]]
  fig, axes = plt.subplots(len(parts), 3, figsize=(15, 4 * len(parts)), squeeze=False)
  for row, (a, b) in enumerate(parts):
    t = np.arange(a, b)
    for c, axis_name in enumerate("xyz"):
      ax = axes[row, c]
      for j in joints:
        ax.plot(t, pos[a:b, j, c], label=sk.joint_names[j], lw=1)
      ax.set_title(f"{axis_name}, frames {a}-{b - 1}")
      ax.set_xlabel("frame")
  axes[0, 0].legend(fontsize=7, loc="best")
  fig.suptitle(f"{motion.name} ({motion.fps:g} fps, up axis {motion.up_axis}, {motion.units})")
  fig.tight_layout()
  return save_figure(fig, path)
