"""Writing motions: one function writes a dance, a set of transitions or takes in every format chorjax
writes (CSV, NPZ, BVH, BVH onto a character, binary glTF, the HTML player), for the command line, the Python API, the
end of training and evaluation alike; and the checks that come before any long work (the output's kind,
files that already exist, the character to retarget onto)."""

from __future__ import annotations

from pathlib import Path

from chorjax.errors import UserError


def output_paths(out: Path, num: int) -> list[Path]:
  """The files ``num`` motions written to ``out`` make: OUT itself, or OUT_k per motion for CSV/BVH."""
  if num == 1 or out.suffix.lower() in (".npz", ".html"):
    return [out]
  return [out.with_name(f"{out.stem}_{k}{out.suffix}") for k in range(num)]


def written_paths(out: Path, num: int, skeleton) -> list[Path]:
  """Every file :func:`write_motions` writes for ``num`` motions of ``skeleton`` at ``out``: the outputs, and
  beside each CSV of a skeleton other than the 16-joint one its sidecar (``data.csv.sidecar_path``)."""
  from chorjax.data.csv import sidecar_path
  from chorjax.data.skeletons import MPII16

  paths = output_paths(out, num)
  if out.suffix.lower() == ".csv" and skeleton.joint_names != MPII16.joint_names:
    paths += [sidecar_path(p) for p in paths]
  return paths


def load_character(path, out: Path):
  """The ``--skeleton`` character a BVH is retargeted onto (read and mapped now, before any long work), or
  None without one."""
  if path is None:
    return None
  if out.suffix.lower() != ".bvh":
    raise UserError(f"--skeleton {path}: retargeting writes BVH; give -o OUT.bvh (not {out.name})")
  from chorjax.data.retarget import Character

  return Character(path)


def write_motions(out: Path, motions, *, settings=None, character=None, title=None) -> list:
  """Writes ``motions`` (of one skeleton and rate) as ``out``'s suffix says: one ``.npz`` with all of them and
  ``settings``, one ``.html`` player (``title``), or a ``.csv`` / ``.bvh`` / ``.glb`` per motion (``output_paths``;
  ``character``: a BVH onto that character's hierarchy). Returns the paths written."""
  import numpy as np

  from chorjax.data.csv import write_csv
  from chorjax.data.npz import write_npz
  from chorjax.render.html import write_player

  suffix, paths, first = out.suffix.lower(), output_paths(out, len(motions)), motions[0]
  if suffix == ".npz":
    positions = np.stack([m.positions for m in motions])
    return [
      write_npz(
        out,
        positions,
        fps=first.fps,
        skeleton=first.skeleton,
        up_axis=first.up_axis,
        units=first.units,
        settings=settings or {},
      )
    ]
  if suffix == ".html":
    return [write_player(motions, out, title=title or out.stem)]
  if suffix == ".bvh":
    from chorjax.data.bvh import write_bvh
    from chorjax.data.mapping import to_mpii16
    from chorjax.data.retarget import write_retargeted

    if character is not None:
      return [write_retargeted(to_mpii16(m), character, path) for m, path in zip(motions, paths)]
    return [write_bvh(m, path) for m, path in zip(motions, paths)]
  if suffix == ".glb":
    from chorjax.data.gltf import write_glb

    return [write_glb(m, path) for m, path in zip(motions, paths)]
  return [write_csv(m, path) for m, path in zip(motions, paths)]


def as_motions(positions, fps, skeleton, up_axis, name: str = "dancer") -> list:
  """Drawn positions ``[K, T, J, 3]`` in a run's data space as motions ``{name} 0``, ``{name} 1`` ..."""
  from chorjax.data.motion import Motion

  return [Motion(p, fps, skeleton, up_axis, units="data", name=f"{name} {k}") for k, p in enumerate(positions)]
