"""The pictures ``chorjax render`` draws, registered as formats (:mod:`chorjax.data.formats`) when the package
is imported: the trajectories or the filmstrip as a PNG, a GIF/MP4 animation, and the HTML player (which
``sample -o``, ``eval`` and the end of training also write)."""

from __future__ import annotations

from pathlib import Path

from chorjax.data.formats import Drawing, Format, Writing, register
from chorjax.render import plot
from chorjax.render.html import write_player
from chorjax.render.video import write_animation


def _write_player(motions, paths, writing: Writing) -> list[Path]:
  return [write_player(motions, paths[0], title=writing.title or paths[0].stem)]


def _draw_player(motions, out: Path, drawing: Drawing) -> Path:
  return write_player(motions, out, title=drawing.title or out.stem, columns=drawing.columns)


def _animation(motions, out: Path, drawing: Drawing) -> Path:
  return write_animation(motions, out, size=drawing.size)


def _picture(motions, out: Path, drawing: Drawing) -> Path:
  if len(motions) > 1:
    drawing.warn(f"note: {out.suffix.lower()} shows one motion; rendering {motions[0].name}")
  if drawing.strip:
    return plot.plot_strip(motions[0], out, every=drawing.every, poses=drawing.poses)
  return plot.plot_trajectories(motions[0], out)


register(Format("PNG", (".png",), draw=_picture, extra="viz"))
register(Format("GIF/MP4", (".gif", ".mp4"), draw=_animation, extra="viz"))
register(Format("HTML player", (".html",), write=_write_player, draw=_draw_player, whole=True))
