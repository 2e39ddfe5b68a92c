"""Stick-figure animations as GIF or MP4 (needs the ``viz`` extra: matplotlib, imageio, imageio-ffmpeg).

Several motions side by side in one video (720p by default), each with a fixed camera and equal axes
framing its whole take, at the first motion's frame rate.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from chorjax.data import transforms
from chorjax.data.motion import Motion
from chorjax.errors import UserError, atomic_write
from chorjax.render.plot import require_matplotlib


@contextlib.contextmanager
def _env(**values):
  """Environment variables set for the duration of the block, then restored."""
  old = {k: os.environ.get(k) for k in values}
  os.environ.update(values)
  try:
    yield
  finally:
    for k, v in old.items():
      if v is None:
        os.environ.pop(k, None)
      else:
        os.environ[k] = v


def _frames_rgb(motions: Sequence[Motion], size: tuple[int, int] = (1280, 720), max_frames: int | None = None):
  """RGB frames ``[H, W, 3]`` of the motions side by side, each in its own 3D panel with a fixed camera
  framing its whole take (the panel's cube is the take's extent, so the figure fills the panel)."""
  plt = require_matplotlib()
  # matplotlib's 3D axes are z-up: plot (x, z, y)
  pts = [np.asarray(transforms.to_y_up(m.positions, m.up_axis))[:max_frames][..., [0, 2, 1]] for m in motions]
  n = max(len(p) for p in pts)
  fig: Any = plt.figure(figsize=(size[0] / 100, size[1] / 100), dpi=100)
  fig.subplots_adjust(left=0, right=1, bottom=0, top=1, wspace=0)
  panels = []
  for k, (m, p) in enumerate(zip(motions, pts)):
    ax: Any = fig.add_subplot(1, len(motions), k + 1, projection="3d")  # Axes3D (stubs type it as 2D)
    lo, hi = p.reshape(-1, 3).min(0), p.reshape(-1, 3).max(0)
    centre, half = (lo + hi) / 2, (hi - lo).max() / 2 or 1.0
    for a, c in zip("xyz", range(3)):
      getattr(ax, f"set_{a}lim")(centre[c] - half, centre[c] + half)
    ax.set_box_aspect((1, 1, 1), zoom=1.1)
    ax.set_xticklabels([])
    ax.set_yticklabels([])
    ax.set_zticklabels([])
    ax.view_init(elev=15, azim=-60)
    lines = [ax.plot([], [], [], color="#1f5fa8", lw=2.5)[0] for _ in m.skeleton.bones]
    dots = ax.plot([], [], [], "o", color="#c0392b", ms=3)[0]
    title = ax.text2D(0.5, 0.95, m.name, transform=ax.transAxes, ha="center", fontsize=11)
    panels.append((m, p, lines, dots, title))
  for t in range(n):
    for m, p, lines, dots, title in panels:
      f = p[min(t, len(p) - 1)]  # a shorter take holds its last frame
      for line, (a, b) in zip(lines, m.skeleton.bones):
        line.set_data_3d(f[[a, b], 0], f[[a, b], 1], f[[a, b], 2])
      dots.set_data_3d(f[:, 0], f[:, 1], f[:, 2])
      title.set_text(f"{m.name}  {min(t, len(p) - 1)}/{len(p)}")
    fig.canvas.draw()
    yield np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
  plt.close(fig)


def write_animation(
  motions: Sequence[Motion], path, size: tuple[int, int] = (1280, 720), max_frames: int | None = None
) -> Path:
  """Writes a GIF or MP4 (by suffix) of the motions side by side, atomically, at the first one's rate."""
  path = Path(path)
  suffix = path.suffix.lower()
  fps = motions[0].fps
  try:
    import imageio.v3 as iio  # the viz extra: chorjax runs without it
  except ImportError:
    raise UserError("this needs imageio: pip install 'chorjax[viz]'") from None
  frames = _frames_rgb(motions, size, max_frames)
  if suffix == ".gif":

    def write(tmp):
      iio.imwrite(tmp, np.stack(list(frames)), extension=".gif", duration=1000.0 / fps, loop=0)
  elif suffix == ".mp4":
    try:
      import imageio_ffmpeg  # the viz extra, for MP4 only
    except ImportError:
      raise UserError("MP4 needs imageio-ffmpeg: pip install 'chorjax[viz]'") from None

    def write(tmp):
      first = next(frames)
      h, w = first.shape[:2]
      # imageio-ffmpeg would start ffmpeg with a Python preexec_fn (os.setpgrp, to keep Ctrl-C from
      # it), which makes CPython run fork handlers, and JAX's handler warns of a deadlock. Without it
      # the child is spawned in C (vfork + exec): no fork of this multithreaded process at all.
      with _env(IMAGEIO_FFMPEG_NO_PREVENT_SIGINT="1"):
        writer = imageio_ffmpeg.write_frames(
          str(tmp),
          (w, h),
          fps=fps,  # pyright: ignore[reportArgumentType] - a float rate is passed to ffmpeg as is
          codec="libx264",
          pix_fmt_out="yuv420p",
          macro_block_size=8,
          output_params=["-f", "mp4"],
        )
        writer.send(None)
      writer.send(first)
      for f in frames:
        writer.send(f)
      writer.close()
  else:
    raise UserError(f"{path}: animations are .gif or .mp4")
  return atomic_write(path, write)
