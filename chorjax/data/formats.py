"""Every file format chorjax reads, writes or draws, declared once: its suffixes, its reader, its writer and
how it draws takes (``chorjax render``), and the extra it needs. Readers (``data info``, training, ``render``'s
inputs, ``data convert``), writers (``sample -o``, ``eval``, the API's ``save``, the end of training, ``live
--record``), ``render`` and the help texts ask it. A new format is one module and one :func:`register`.

A reader takes ``(path, Reading)`` and returns the file's motions (one for a take, several for a file of
dancers). A writer takes ``(motions, paths, Writing)``: the paths :func:`output_paths` gives (one file for a
format that holds every motion, ``OUT_k`` per motion otherwise) and returns what it wrote. A drawer takes
``(motions, out, Drawing)`` and returns the picture's path.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from chorjax.data.mapping import to_mpii16
from chorjax.data.retarget import write_retargeted
from chorjax.errors import UserError, either


@dataclass(frozen=True)
class Reading:
  """What a reader may need beyond the file: a CSV's skeleton, rate and up axis (CSV records none of them); an
  AMC's skeleton file (``asf``, else found beside it) and rate (AMC records none: 120, CMU's, unless told)."""

  skeleton: str = "mpii16"
  fps: float = 30.0
  up_axis: str = "-y"
  asf: Any = None
  amc_fps: float = 120.0


@dataclass(frozen=True)
class Writing:
  """What a writer may take beside the motions: the draw's ``settings`` (kept by a file that holds them), a
  ``character`` to retarget onto (BVH) and a page's ``title``."""

  settings: dict = field(default_factory=dict)
  character: Any = None
  title: str | None = None


@dataclass(frozen=True)
class Drawing:
  """How ``chorjax render`` draws: a video's ``size`` (pixels), a page's ``columns`` and ``title``, a PNG's
  filmstrip (``strip``: ``poses`` a row, ``every`` frames apart) and where a note goes (``warn``)."""

  size: tuple[int, int] = (1280, 720)
  columns: int | None = None
  title: str | None = None
  strip: bool = False
  every: int = 6
  poses: int = 12
  warn: Callable[[str], None] = print


@dataclass(frozen=True)
class Format:
  """One file format. ``whole``: every motion goes into one file (else ``OUT_k`` per motion); ``beside``: the
  files a writer puts next to one output for a motion (a CSV's skeleton sidecar); ``extra``: the pip extra its
  reader, writer or drawer needs."""

  name: str
  suffixes: tuple[str, ...]
  read: Callable[[Path, Reading], list] | None = None
  write: Callable[[list, list[Path], Writing], list[Path]] | None = None
  draw: Callable[[list, Path, Drawing], Path] | None = None
  whole: bool = False
  beside: Callable[[Any, Path], list[Path]] | None = None  # (skeleton, output) -> files beside it
  extra: str = ""


FORMATS: dict[str, Format] = {}  # suffix -> format


def register(fmt: Format) -> Format:
  """Adds ``fmt`` under each of its suffixes (lower case, with the dot); a suffix already taken is refused."""
  for suffix in fmt.suffixes:
    if not suffix.startswith(".") or suffix != suffix.lower():
      raise ValueError(f"{fmt.name}: suffix {suffix!r} must be lower case and start with a dot")
    if suffix in FORMATS and FORMATS[suffix] is not fmt:
      raise ValueError(f"{fmt.name}: {suffix} is already {FORMATS[suffix].name}'s")
  FORMATS.update(dict.fromkeys(fmt.suffixes, fmt))
  return fmt


def unregister(fmt: Format) -> None:
  """Removes ``fmt``'s suffixes (a test's toy format)."""
  for suffix in fmt.suffixes:
    if FORMATS.get(suffix) is fmt:
      del FORMATS[suffix]


def suffixes(role: str) -> tuple[str, ...]:
  """The suffixes of every format that can ``role``: ``"read"``, ``"write"`` or ``"draw"``."""
  return tuple(s for s, f in FORMATS.items() if getattr(f, role) is not None)


def listed(role: str) -> str:
  """``role``'s suffixes as a phrase: ``.csv, .npz or .bvh``."""
  return either(suffixes(role))


def format_of(path, role: str) -> Format:
  """The format that can ``role`` the file ``path`` by its suffix, or a one-line ``UserError`` naming the
  suffixes that can."""
  suffix = Path(path).suffix.lower()
  fmt = FORMATS.get(suffix)
  if fmt is None or getattr(fmt, role) is None:
    what = {"read": "motion format", "write": "output", "draw": "picture"}[role]
    raise UserError(f"{path}: unsupported {what} {suffix or '(no suffix)'!r} (supported: {listed(role)})")
  return fmt


def read(path, reading: Reading | None = None) -> list:
  """Every motion in the file ``path`` (one for a take, K for a file of K dancers)."""
  return format_of(path, "read").read(Path(path), reading or Reading())  # type: ignore[misc]


def output_paths(out: Path, num: int) -> list[Path]:
  """The files ``num`` motions written to ``out`` make: OUT itself, or OUT_k per motion for a format that holds
  one motion a file."""
  fmt = FORMATS.get(out.suffix.lower())
  if num == 1 or (fmt is not None and fmt.whole):
    return [out]
  return [out.with_name(f"{out.stem}_{k}{out.suffix}") for k in range(num)]


def written_paths(out: Path, num: int, skeleton) -> list[Path]:
  """Every file :func:`write` writes for ``num`` motions of ``skeleton`` at ``out``: the outputs and what goes
  beside each (a CSV's sidecar, for a skeleton other than the 16-joint one)."""
  paths = output_paths(out, num)
  fmt = FORMATS.get(out.suffix.lower())
  if fmt is None or fmt.beside is None:
    return paths
  return paths + [p for path in paths for p in fmt.beside(skeleton, path)]


def write(out: Path, motions: Sequence, writing: Writing | None = None) -> list[Path]:
  """Writes ``motions`` (of one skeleton and rate) as ``out``'s suffix says. Returns the paths written."""
  fmt = format_of(out, "write")
  return fmt.write(list(motions), output_paths(out, len(motions)), writing or Writing())  # type: ignore[misc]


def draw(motions: Sequence, out: Path, drawing: Drawing | None = None) -> Path:
  """Draws ``motions`` to ``out`` as its suffix says."""
  return format_of(out, "draw").draw(list(motions), out, drawing or Drawing())  # type: ignore[misc]


# The motion formats chorjax ships (numpy only). The pictures (PNG, GIF/MP4 and the HTML player) are
# chorjax.render's, registered by that package when it is imported (chorjax.render.drawers).
from chorjax.data import amc, bvh, c3d, csv, gltf, npz  # noqa: E402
from chorjax.data.skeletons import get_skeleton  # noqa: E402


def _per_motion(write_one: Callable[[Any, Path], Path]):
  """A writer for a format of one motion a file."""
  return lambda motions, paths, writing: [write_one(m, p) for m, p in zip(motions, paths)]


def _write_npz(motions, paths, writing: Writing) -> list[Path]:
  first = motions[0]
  positions = np.stack([m.positions for m in motions])
  meta = {"fps": first.fps, "skeleton": first.skeleton, "up_axis": first.up_axis, "units": first.units}
  return [npz.write_npz(paths[0], positions, **meta, settings=writing.settings)]


def _write_bvh(motions, paths, writing: Writing) -> list[Path]:
  if writing.character is None:
    return [bvh.write_bvh(m, p) for m, p in zip(motions, paths)]

  return [write_retargeted(to_mpii16(m), writing.character, p) for m, p in zip(motions, paths)]


register(
  Format(
    "CSV",
    (".csv",),
    read=lambda p, r: [csv.read_csv(p, skeleton=get_skeleton(r.skeleton), fps=r.fps, up_axis=r.up_axis)],
    write=_per_motion(csv.write_csv),
    beside=csv.sidecars,
  )
)
register(Format("NPZ", (".npz",), read=lambda p, r: npz.read_npz(p), write=_write_npz, whole=True))
register(Format("BVH", (".bvh",), read=lambda p, r: [bvh.read_bvh(p)], write=_write_bvh))
register(Format("ASF/AMC", (".amc",), read=lambda p, r: [amc.read_amc(p, r.asf, fps=r.amc_fps)]))
register(Format("C3D", (".c3d",), read=lambda p, r: [c3d.read_c3d(p)], extra="c3d"))
register(Format("glTF", (".glb",), write=_per_motion(gltf.write_glb), extra="export"))
