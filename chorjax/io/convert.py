"""Converting takes (``chorjax data convert``): BVH, ASF/AMC, C3D or CSV read as training reads them, mapped
onto the 16 training joints if asked, made like a reference dataset (``like``: its up axis, body size,
frame rate and root position), and written to the training CSV layout or to one BVH."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from chorjax.data import formats, transforms
from chorjax.data.bvh import write_bvh
from chorjax.data.csv import write_csv, written_paths
from chorjax.data.dataset import read_motions, read_takes, resolve_files, to_rate, to_up_axis
from chorjax.data.mapping import map_takes, to_mpii16
from chorjax.data.rest import drop_leading_rests
from chorjax.data.retarget import write_retargeted
from chorjax.errors import UserError, is_run_folder, refuse_existing
from chorjax.evaluation.metrics import body_size
from chorjax.io.output import load_character

# Names that say a file of a format data convert does not write (every registered format's but CSV's, BVH's and
# NPZ's, which a folder of converted CSVs may be named after, and a few more): refused as -o, they would become
# a folder of CSVs (a folder named like a take, x.csv, still holds the converted take)
OTHER_FILES = (".gltf", ".asf", ".json", ".onnx", ".zip")


def convert(
  inputs: Sequence[str],
  output,
  *,
  joints: str = "mpii16",
  joint_map=None,
  like: str | None = None,
  up_axis: str | None = None,
  scale: float = 1.0,
  asf=None,
  amc_fps: float = 120.0,
  fps: float = 30.0,
  drop_first_frame: bool = False,
  keep_rest_frames: bool = False,
  rigid: bool = False,
  skeleton=None,
  force: bool = False,
  log: Callable[[str], None] = print,
) -> list:
  """Converts the takes of ``inputs`` (files or folders) and writes them to ``output``: a folder (one CSV a
  take) or one ``.bvh`` (onto ``skeleton``, a character BVH, where given). ``log`` hears what was done on
  the way (rest frames dropped, how joints were mapped). Returns ``[(path written, motion)]``."""
  out = Path(output)
  files = (*(s for s in formats.FORMATS if s not in (".csv", ".bvh", ".npz")), *OTHER_FILES)
  if out.suffix.lower() in files and not out.is_dir():  # a file's name, not a folder for the CSVs
    raise UserError(
      f"-o {out}: data convert writes a folder of CSVs or one .bvh file; for {out.suffix} read the takes and "
      "write them with chorjax sample's or Motion.write's formats"
    )
  character = load_character(skeleton, out)
  if joint_map is not None and joints != "mpii16" and character is None:
    raise UserError(f"{joint_map}: a joint map places the 16 training joints: give --joints mpii16 with it")
  motions = [
    m for spec in inputs for f in resolve_files(spec) for m in read_motions(f, fps=fps, asf=asf, amc_fps=amc_fps)
  ]
  motions = _without_rest(motions, drop_first_frame, keep_rest_frames, log)
  if joints == "mpii16":
    motions, used = map_takes(motions, joint_map)
    for how in dict.fromkeys(m.describe() for m in used.values()):
      log(f"joints mapped {how}")
  if like:
    motions = like_reference(motions, like)
  if up_axis:
    motions = [to_up_axis(m, up_axis) for m in motions]
  if scale != 1.0:
    motions = [m.replace(positions=m.positions * np.float32(scale)) for m in motions]
  return _write(motions, out, character, joint_map, rigid, force)


def _without_rest(motions, drop_first_frame: bool, keep_rest_frames: bool, log) -> list:
  """The takes without a converter's leading rest pose (or without their first frame, where asked)."""
  if drop_first_frame:
    if short := [m for m in motions if m.num_frames < 2]:
      raise UserError(f"{short[0].source or short[0].name}: one frame; --drop-first-frame would leave none")
    return [m.replace(positions=m.positions[1:]) for m in motions]
  if keep_rest_frames:
    return motions

  motions, note = drop_leading_rests(motions, "--keep-rest-frames")
  if note:
    log(note)
  return motions


def like_reference(motions, like: str) -> list:
  """``motions`` made like the takes of ``like`` (a bundled name, folder or file): their up axis and units,
  their mean body size, their frame rate, and the same average place of the root (the root is absolute in
  the features)."""
  ref = read_takes([like])
  canon = lambda m: np.asarray(transforms.to_y_up(m.positions, m.up_axis))
  ref_size = np.mean([body_size(canon(r), r.skeleton) for r in ref])
  if not (np.isfinite(ref_size) and ref_size > 0):  # every take scaled to nothing, written without a word
    raise UserError(f"--like {like}: its joints have no extent (body size {ref_size:g}): nothing to scale to")
  motions = [to_up_axis(m, ref[0].up_axis) for m in motions]
  sizes = [body_size(canon(m), m.skeleton) for m in motions]
  for m, size in zip(motions, sizes, strict=True):
    if not (np.isfinite(size) and size > 0):
      raise UserError(f"{m.source or m.name}: its joints have no extent (body size {size:g}): --like cannot scale it")
  motions = [
    m.replace(positions=m.positions * np.float32(ref_size / size), units=ref[0].units)
    for m, size in zip(motions, sizes, strict=True)
  ]
  motions = [to_rate(m, ref[0].fps) for m in motions]
  ref_root = np.mean([r.positions[:, r.skeleton.root].mean(0) for r in ref], axis=0)
  return [m.replace(positions=m.positions - m.positions[:, m.skeleton.root].mean(0) + ref_root) for m in motions]


def _write(motions, out: Path, character, joint_map, rigid: bool, force: bool) -> list:
  """One BVH (``out.bvh``, onto ``character`` where given) or one CSV a take in the folder ``out``."""
  if out.suffix.lower() == ".bvh":
    if len(motions) != 1:
      raise UserError(f"{out}: one .bvh holds one motion; give one input or an output folder")

    refuse_existing([out], force)
    if character is not None:
      return [(write_retargeted(to_mpii16(motions[0], joint_map), character, out), motions[0])]
    return [(write_bvh(motions[0], out, exact=not rigid), motions[0])]
  if is_run_folder(out):
    raise UserError(f"-o {out}: a chorjax run's folder; write the converted takes into a folder of their own")
  targets = [out / f"{m.name}.csv" for m in motions]
  first: dict = {}
  for m, t in zip(motions, targets):  # two takes of one name would be one file: refused before any is written
    if t in first:
      raise UserError(
        f"{first[t].source or first[t].name} and {m.source or m.name} would both be written to {t}; "
        "convert them into different folders"
      )
    first[t] = m
  refuse_existing([p for m, t in zip(motions, targets) for p in written_paths(m, t)], force)  # sidecars too
  return [(write_csv(m, t), m) for m, t in zip(motions, targets)]
