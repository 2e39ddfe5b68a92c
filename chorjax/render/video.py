"""Stick-figure animations as GIF or MP4 (needs the ``viz`` extra: matplotlib, imageio, imageio-ffmpeg).

Fixed camera and equal axes over the whole take, at the motion's own frame rate.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from chorjax.data import transforms
from chorjax.data.motion import Motion
from chorjax.errors import UserError, atomic_write
from chorjax.render.plot import require_matplotlib


def _frames_rgb(motion: Motion, size: int = 400, max_frames: int | None = None):
  plt = require_matplotlib()
  pos = np.asarray(transforms.to_y_up(motion.positions, motion.up_axis))
  if max_frames:
    pos = pos[:max_frames]
  # matplotlib's 3D axes are z-up: plot (x, z, y)
  pts = pos[..., [0, 2, 1]]
  lo, hi = pts.reshape(-1, 3).min(0), pts.reshape(-1, 3).max(0)
  centre, half = (lo + hi) / 2, (hi - lo).max() / 2 or 1.0
  fig: Any = plt.figure(figsize=(size / 100, size / 100), dpi=100)
  ax: Any = fig.add_subplot(projection="3d")  # Axes3D: matplotlib's stubs type it as 2D axes
  ax.set_box_aspect((1, 1, 1))
  bones = motion.skeleton.bones
  lines: list[Any] = [ax.plot([], [], [], color="#1f5fa8", lw=2)[0] for _ in bones]
  dots: Any = ax.plot([], [], [], "o", color="#c0392b", ms=2)[0]
  for a, c in zip("xyz", range(3)):
    getattr(ax, f"set_{a}lim")(centre[c] - half, centre[c] + half)
  ax.set_xticklabels([])
  ax.set_yticklabels([])
  ax.set_zticklabels([])
  ax.view_init(elev=15, azim=-60)
  title = ax.set_title(motion.name, fontsize=8)
  for t in range(pos.shape[0]):
    for line, (p, c) in zip(lines, bones):
      line.set_data_3d(pts[t, [p, c], 0], pts[t, [p, c], 1], pts[t, [p, c], 2])
    dots.set_data_3d(pts[t, :, 0], pts[t, :, 1], pts[t, :, 2])
    title.set_text(f"{motion.name}  {t}/{pos.shape[0]}")
    fig.canvas.draw()
    yield np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
  plt.close(fig)


def write_animation(motion: Motion, path, size: int = 400, max_frames: int | None = None) -> Path:
  """Writes a GIF or MP4 (by suffix) atomically."""
  path = Path(path)
  suffix = path.suffix.lower()
  try:
    import imageio.v3 as iio
  except ImportError:
    raise UserError("this needs imageio: pip install 'chorjax[viz]'") from None
  frames = _frames_rgb(motion, size, max_frames)
  if suffix == ".gif":

    def write(tmp):
      iio.imwrite(tmp, np.stack(list(frames)), extension=".gif", duration=1000.0 / motion.fps, loop=0)
  elif suffix == ".mp4":
    try:
      import imageio_ffmpeg
    except ImportError:
      raise UserError("MP4 needs imageio-ffmpeg: pip install 'chorjax[viz]'") from None

    def write(tmp):
      first = next(frames)
      h, w = first.shape[:2]
      writer = imageio_ffmpeg.write_frames(
        str(tmp),
        (w, h),
        fps=motion.fps,  # pyright: ignore[reportArgumentType] - a float rate is passed to ffmpeg as is
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
