"""What ``chorjax sample`` and ``Run.sample`` draw: a run's dancers, conditioned on a take id or a blend and
optionally continuing a real phrase (``--prime``), drawn by the run's family; and real phrases read as
training read its takes.
"""

from __future__ import annotations

from pathlib import Path

import jax
import numpy as np

from chorjax.data.dataset import conform, read_takes
from chorjax.data.formats import output_paths, suffixes, written_paths
from chorjax.errors import UserError, check_output, refuse_existing
from chorjax.io.output import as_motions, load_character, write_motions
from chorjax.run import load_run


def read_prime(spec: str, features, data_cfg) -> np.ndarray:
  """``FILE[:START:LEN]`` -> normalized frames ``[P, D]`` of a real phrase, read as training read its
  takes (``data_cfg`` is the run's DataConfig: joints mapped, rotated to its up axis)."""
  return np.asarray(features.encode(read_phrase(spec, features, data_cfg)), np.float32)


def read_phrase(spec: str, features, data_cfg, flag: str = "--prime") -> np.ndarray:
  """``FILE[:START:LEN]`` -> the phrase's positions ``[P, J, 3]`` in the run's data space (see
  :func:`read_prime`; ``flag`` names the setting in errors)."""
  parts = spec.rsplit(":", 2)
  if len(parts) == 3 and all(x.isascii() and x.isdigit() for x in parts[1:]):
    path, start, length = Path(parts[0]), int(parts[1]), int(parts[2])
  elif len(parts) == 3 and not Path(spec).exists() and Path(parts[0]).exists():
    raise UserError(f"{flag} {spec}: START and LEN must be whole numbers (FILE:START:LEN, e.g. {parts[0]}:0:60)")
  else:
    path, start, length = Path(spec), 0, None
  motion = conform(read_takes([str(path)], data_cfg)[:1], data_cfg, rest=False)[0]  # frames as in the file
  if motion.skeleton.num_joints != features.skeleton.num_joints:
    raise UserError(
      f"{path}: {motion.skeleton.num_joints} joints; the model was trained on {features.skeleton.num_joints}"
    )
  end = motion.num_frames if length is None else start + length
  if start >= motion.num_frames or end > motion.num_frames or end - start < 2:
    raise UserError(
      f"{flag} {spec}: frames {start}..{end} are not inside the take's {motion.num_frames} frames (need at least 2)"
    )
  phrase = np.asarray(motion.positions[start:end], np.float32)
  flat = np.flatnonzero(np.ptp(phrase, axis=1).max(-1) == 0)  # frames whose joints all sit at one point
  if len(flat):
    raise UserError(f"{flag} {spec}: frame {start + flat[0]} has every joint at one point: no body to continue from")
  return phrase


def read_pose(spec: str, features, data_cfg, flag: str = "--to") -> np.ndarray:
  """``FILE[:FRAME]`` (frame 0 unless given) -> that frame's positions ``[J, 3]`` in the run's data space."""
  path, colon, frame = spec.rpartition(":")
  if not colon or not (frame.isascii() and frame.isdigit()):
    path, frame = spec, "0"
  take = read_phrase(path, features, data_cfg, flag=flag)
  if int(frame) >= len(take):
    raise UserError(f"{flag} {spec}: frame {frame} is not inside the take's {len(take)} frames")
  return take[int(frame)]


def check_counts(**counts) -> None:
  """Refuses a ``frames``, ``num`` or ``seed`` that is no whole number (a bool, a float, text) or lies outside
  1 (``seed``: 0) .. 2**32 - 1, in one line naming it."""
  for name, value in counts.items():
    low = 0 if name == "seed" else 1
    if not isinstance(value, int) or isinstance(value, bool) or not low <= value < 2**32:
      raise UserError(f"{name} {value!r}: must be a whole number from {low} to 2**32 - 1")


def sample_dancers(run, frames: int, num: int, seed: int, prime=None, motion=None, mix=None, controls=None):
  """``(positions [num, frames (+ prime), J, 3] in data space, settings)``: what ``chorjax sample`` and
  ``Run.sample`` draw. ``run``: a loaded run; ``prime``: ``FILE[:START:LEN]``; ``motion`` / ``mix``: the take
  id or blend that conditions the dance; ``controls``: sampling controls (unset: the run's own)."""
  check_counts(frames=frames, num=num, seed=seed)
  run = run.serving("sample")
  if not run.family.conditioned and (motion is not None or mix is not None):
    flag = "--motion" if motion is not None else "--mix"
    raise UserError(f"{flag}: a {run.family.name} run draws from noise alone; it is conditioned on no take or label")
  run.check_drawn(frames * num, f"frames {frames} x num {num}")
  sampling = run.sampling(**(controls or {}))
  run = run.ranged(sampling)
  motion_BxM = np.tile(run.motion_weights(motion, mix)[None], (num, 1))
  primed = None
  if prime:
    primed = np.tile(read_prime(prime, run.features, run.config.data)[None], (num, 1, 1))
  pos = run.family.dance(
    run.graphdef, run.params, run.features, motion_BxM, jax.random.key(seed), frames, sampling, primed
  )
  settings = {
    "workdir": str(run.workdir),
    "checkpoint_step": run.step,
    "frames": frames,
    "motion": motion,
    "mix": mix,
    "prime": prime,
    "seed": seed,
    **sampling.to_dict(),
  }
  return pos, settings


def write_sample(
  workdir,
  output,
  *,
  frames: int = 1000,
  num: int = 1,
  seed: int = 0,
  prime=None,
  motion=None,
  mix=None,
  controls: dict | None = None,
  checkpoint="kept",
  skeleton=None,
  force: bool = False,
) -> list:
  """``chorjax sample``: draws ``num`` dancers of ``frames`` frames from the run in ``workdir`` (see
  :func:`sample_dancers`) and writes them to ``output`` (``output.write_motions``: CSV, NPZ with the
  settings, BVH, onto the character ``skeleton`` where given, or HTML). Everything that can be refused is
  refused before the draw; an existing file is not replaced unless ``force``. Returns the paths written."""
  check_counts(frames=frames, num=num, seed=seed)  # before any arithmetic on them
  out, _ = check_output(output, suffixes("write"))
  character = load_character(skeleton, out)
  run = load_run(workdir, checkpoint).serving("sample")
  if character is not None and run.features.skeleton.name != "mpii16":
    raise UserError(f"--skeleton: {workdir} dances on its own skeleton, not the 16 joints it retargets from")
  run.check_drawn(frames * num, f"--frames {frames} x --num {num}")  # before naming 10^7 files
  refuse_existing(written_paths(out, num, run.features.skeleton), force)  # OUT_k.csv for several, sidecars
  pos, settings = sample_dancers(run, frames, num, seed, prime, motion, mix, controls)
  settings["workdir"] = str(workdir)
  motions = as_motions(pos, run.fps, run.features.skeleton, run.features.up_axis)
  return write_motions(out, motions, settings=settings, character=character, title=f"chorjax sample ({workdir})")


def write_inbetween(
  workdir, output, *, start: str, to, frames, seed: int = 0, num: int = 1, checkpoint="kept", force: bool = False
) -> list:
  """``chorjax inbetween``: ``num`` pieces of the context phrase ``start`` (``FILE[:START:LEN]``), then for each
  target pose of ``to`` (``FILE[:FRAME]``) the frames a run of a family that writes transitions puts before
  it (``frames``: one count for every target, or one for all) and the target; written to ``output`` as
  :func:`write_sample` writes. Returns the paths written."""
  to, frames = list(to), list(frames)
  if len(frames) == 1:
    frames *= len(to)
  if len(frames) != len(to):
    raise UserError(f"--frames: give one count for every --to, or one for all ({len(to)} --to, {len(frames)} --frames)")
  for n in frames:
    if n < 1:
      raise UserError(f"--frames {n}: must be at least 1")
  out, _ = check_output(output, suffixes("write"))
  refuse_existing(output_paths(out, num), force)
  run = load_run(workdir, checkpoint).serving("inbetween")
  run.check_drawn(sum(frames) * num, f"--frames {' '.join(map(str, frames))} x --num {num}")
  context = read_phrase(start, run.features, run.config.data, flag="--from")
  targets = [read_pose(t, run.features, run.config.data) for t in to]
  pieces = run.family.transitions(run, context, targets, frames, jax.random.key(seed), num)
  settings = {
    "workdir": str(workdir),
    "checkpoint_step": run.step,
    "from": start,
    "to": to,
    "frames": frames,
    "seed": seed,
  }
  motions = as_motions(pieces, run.fps, run.features.skeleton, run.features.up_axis)
  return write_motions(out, motions, settings=settings, title=f"chorjax sample ({workdir})")
