"""Static plots: trajectories of the pelvis and the end joints (needs the ``viz`` extra)."""

from __future__ import annotations

import importlib
from pathlib import Path

import numpy as np

from chorjax.data import transforms
from chorjax.data.motion import Motion
from chorjax.errors import UserError, atomic_write


def require_matplotlib():
  """``matplotlib.pyplot`` on the Agg backend, or a UserError naming the viz extra."""
  try:
    import matplotlib  # the viz extra: chorjax runs without it

    matplotlib.use("Agg")
    return importlib.import_module("matplotlib.pyplot")
  except ImportError:
    raise UserError("this needs matplotlib: pip install 'chorjax[viz]'") from None


def _figure_class():
  require_matplotlib()
  return importlib.import_module("matplotlib.figure").Figure


def save_figure(fig, path) -> Path:
  """Writes a matplotlib figure atomically (format from the suffix, PNG by default) and closes it."""
  plt = require_matplotlib()
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


def strip_rows(num_frames: int, every: int, poses: int) -> list[tuple[str, int]]:
  """``(label, first frame)`` of the filmstrip rows: start, middle and end (fewer when short)."""
  span = every * (poses - 1) + 1
  if num_frames <= span:
    return [("whole", 0)]
  rows = [("start", 0)]
  if num_frames >= 3 * span:  # a middle row only where it overlaps neither
    rows.append(("middle", (num_frames - span) // 2))
  return [*rows, ("end", num_frames - span)]


def draw_strip(ax, pos_TxJx3, skeleton, frames, spacing: float) -> None:
  """Front view (x right, y up) of the poses at ``frames``, side by side, each about its own root."""
  for k, t in enumerate(frames):
    p = pos_TxJx3[t] - pos_TxJx3[t, skeleton.root] * np.array([1.0, 0.0, 1.0]) + np.array([k * spacing, 0.0, 0.0])
    for a, b in skeleton.bones:
      ax.plot(p[[a, b], 0], p[[a, b], 1], color="#1f5fa8", lw=1.5)
    ax.plot(p[:, 0], p[:, 1], "o", color="#c0392b", ms=1.5)
    ax.text(k * spacing, pos_TxJx3[:, :, 1].min() - 0.08 * spacing, str(t), ha="center", fontsize=6)
  ax.set_aspect("equal")
  ax.axis("off")


def plot_strip(motion: Motion, path, every: int = 6, poses: int = 12) -> Path:
  """Filmstrips of a motion written to ``path`` (PNG by default): see :func:`strip_figure`."""
  fig = strip_figure(motion, every, poses)
  fmt = (Path(path).suffix or ".png").lstrip(".")
  return atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=80, format=fmt))


def strip_figure(motion: Motion, every: int = 6, poses: int = 12):
  """Filmstrips of a motion as a matplotlib figure: ``poses`` stick figures ``every`` frames apart, at the
  start, middle and end.

  A dance that freezes shows the same figure over and over in the end row; one that trembles, the
  same figure with its limbs slightly shaken. Positions are drawn y-up, each pose centred on its root.
  """
  figure = _figure_class()  # no pyplot: drawing a strip never changes a notebook's own plotting backend
  pos = np.asarray(transforms.to_y_up(motion.positions, motion.up_axis), np.float64)
  sk = motion.skeleton
  height = float(np.ptp(pos[:, :, 1], axis=1).mean()) or 1.0
  rows = strip_rows(motion.num_frames, every, poses)
  fig = figure(figsize=(poses * 0.9, 1.9 * len(rows)))
  axes = fig.subplots(len(rows), 1, squeeze=False)
  for ax, (label, start) in zip(axes[:, 0], rows):
    frames = [t for t in range(start, start + every * poses, every) if t < motion.num_frames]
    draw_strip(ax, pos, sk, frames, spacing=0.7 * height)
    ax.set_title(f"{label}: frames {frames[0]}-{frames[-1]}, every {every}", fontsize=8, loc="left")
  fig.suptitle(f"{motion.name} ({motion.num_frames} frames, {motion.fps:g} fps)", fontsize=9)
  fig.tight_layout()
  return fig
