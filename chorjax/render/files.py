"""``chorjax render``: takes drawn to a file: the HTML player, a GIF or MP4 animation, the trajectories plot or
the filmstrip (``strip``) as a PNG."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from chorjax.data import formats
from chorjax.data.dataset import read_motions, read_takes, resolve_files
from chorjax.errors import UserError, check_output, refuse_existing
from chorjax.render.plot import plot_trajectories

MAX_SIDE = 7680  # pixels: 8K video's width
MAX_POSES = 200  # strip: poses per row (a row of 200 is already wider than any screen)


def parse_size(text: str) -> tuple[int, int]:
  """``WxH`` -> (W, H), both even and at least 64 (video codecs want even sizes)."""
  w, _, h = text.lower().partition("x")
  if not (w.isdigit() and h.isdigit()) or not (64 <= int(w) <= MAX_SIDE and 64 <= int(h) <= MAX_SIDE):
    raise UserError(
      f"--size {text}: expected WIDTHxHEIGHT in pixels, e.g. 1280x720 (each side 64 to {MAX_SIDE}, 8K video's width)"
    )
  return int(w) // 2 * 2, int(h) // 2 * 2


def render(
  inputs,
  output,
  *,
  frames: int | None = None,
  fps: float = 30.0,
  size: str = "1280x720",
  columns: int | None = None,
  title: str | None = None,
  strip: bool = False,
  every: int = 6,
  poses: int = 12,
  force: bool = False,
  warn: Callable[[str], None] = print,
) -> Path:
  """Draws the takes of ``inputs`` (files or folders; CSV at ``fps``) to ``output`` as its suffix says:
  ``.html`` (the player, ``columns`` side by side, ``title``), ``.gif``/``.mp4`` (``size``: ``WxH``),
  ``.png`` (the first take's trajectories, or its filmstrip with ``strip``: ``poses`` a row, ``every``
  frames apart). ``frames``: the first N frames only. Returns the path written."""
  if poses > MAX_POSES:
    raise UserError(f"--poses {poses}: at most {MAX_POSES} poses in a row")
  out, suffix = check_output(output, formats.suffixes("draw"))
  if strip and suffix != ".png":
    raise UserError(f"{out}: --strip draws a PNG")
  refuse_existing([out], force)
  motions = [m for spec in inputs for f in resolve_files(spec) for m in read_motions(f, fps=fps)]
  if frames:
    motions = [m.replace(positions=m.positions[:frames]) for m in motions]
  drawing = formats.Drawing(
    size=parse_size(size), columns=columns, title=title, strip=strip, every=every, poses=poses, warn=warn
  )
  return formats.draw(motions, out, drawing)


def plot_file(path, output, *, split: int = 200) -> Path:
  """``chorjax data plot``: the trajectories of the one take in ``path`` as a PNG (``split``: frames in the
  first row)."""
  motions = read_takes([path])
  if len(motions) != 1:
    raise UserError(f"{path}: holds {len(motions)} takes; plot one file at a time")
  return plot_trajectories(motions[0], output, split=split)
