"""Writing motions: one function writes a dance, a set of transitions or takes in every format chorjax
writes (CSV, NPZ, BVH, BVH onto a character, binary glTF, the HTML player), for the command line, the Python API, the
end of training and evaluation alike; and the checks that come before any long work (the output's kind,
files that already exist, the character to retarget onto)."""

from __future__ import annotations

from pathlib import Path

from chorjax.data import formats
from chorjax.data.motion import Motion
from chorjax.data.retarget import Character
from chorjax.errors import UserError
from chorjax.render import drawers  # noqa: F401  (registers the HTML player's writer)


def load_character(path, out: Path):
  """The ``--skeleton`` character a BVH is retargeted onto (read and mapped now, before any long work), or
  None without one."""
  if path is None:
    return None
  if out.suffix.lower() != ".bvh":
    raise UserError(f"--skeleton {path}: retargeting writes BVH; give -o OUT.bvh (not {out.name})")

  return Character(path)


def write_motions(out: Path, motions, *, settings=None, character=None, title=None) -> list:
  """Writes ``motions`` (of one skeleton and rate) as ``out``'s suffix says (:mod:`chorjax.data.formats`): one
  ``.npz`` with all of them and ``settings``, one ``.html`` player (``title``), or a ``.csv`` / ``.bvh`` /
  ``.glb`` per motion (``output_paths``; ``character``: a BVH onto that character's hierarchy). Returns the
  paths written."""
  return formats.write(out, motions, formats.Writing(settings=settings or {}, character=character, title=title))


def as_motions(positions, fps, skeleton, up_axis, name: str = "dancer") -> list:
  """Drawn positions ``[K, T, J, 3]`` in a run's data space as motions ``{name} 0``, ``{name} 1`` ..."""
  return [Motion(p, fps, skeleton, up_axis, units="data", name=f"{name} {k}") for k, p in enumerate(positions)]
