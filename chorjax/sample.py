"""What ``chorjax sample`` and ``Run.sample`` draw: a run's dancers, conditioned on a take id or a blend and
optionally continuing a real phrase (``--prime``), drawn by the run's family; and real phrases read as
training read its takes.
"""

from __future__ import annotations

from pathlib import Path

import jax
import numpy as np

from chorjax.data.dataset import conform, read_takes
from chorjax.errors import UserError


def read_prime(spec: str, features, data_cfg) -> np.ndarray:
  """``FILE[:START:LEN]`` -> normalized frames ``[P, D]`` of a real phrase, read as training read its
  takes (``data_cfg`` is the run's DataConfig: joints mapped, rotated to its up axis)."""
  return np.asarray(features.encode(read_phrase(spec, features, data_cfg)), np.float32)


def read_phrase(spec: str, features, data_cfg, flag: str = "--prime") -> np.ndarray:
  """``FILE[:START:LEN]`` -> the phrase's positions ``[P, J, 3]`` in the run's data space (see
  :func:`read_prime`; ``flag`` names the setting in errors)."""
  parts = spec.rsplit(":", 2)
  if len(parts) == 3 and parts[1].isdigit() and parts[2].isdigit():
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
  return np.asarray(motion.positions[start:end], np.float32)


def read_pose(spec: str, features, data_cfg, flag: str = "--to") -> np.ndarray:
  """``FILE[:FRAME]`` (frame 0 unless given) -> that frame's positions ``[J, 3]`` in the run's data space."""
  path, colon, frame = spec.rpartition(":")
  if not colon or not frame.isdigit():
    path, frame = spec, "0"
  take = read_phrase(path, features, data_cfg, flag=flag)
  if int(frame) >= len(take):
    raise UserError(f"{flag} {spec}: frame {frame} is not inside the take's {len(take)} frames")
  return take[int(frame)]


def sample_dancers(run, frames: int, num: int, seed: int, prime=None, motion=None, mix=None, controls=None):
  """``(positions [num, frames (+ prime), J, 3] in data space, settings)``: what ``chorjax sample`` and
  ``Run.sample`` draw. ``run``: a loaded run; ``prime``: ``FILE[:START:LEN]``; ``motion`` / ``mix``: the take
  id or blend that conditions the dance; ``controls``: sampling controls (unset: the run's own)."""
  from chorjax.models import motion_weight_vector

  run = run.serving("sample")
  sampling = run.sampling(**(controls or {}))
  run = run.ranged(sampling)
  motion_BxM = np.tile(motion_weight_vector(run.num_motions, motion, mix)[None], (num, 1))
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
    **sampling,
  }
  return pos, settings
