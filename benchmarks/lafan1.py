"""The in-betweening benchmark, LaFAN1's protocol adapted (Harvey et al. 2020): every take's windows every 40
frames, a context phrase and a target pose, the transitions of 5, 15, 30 and 45 frames written by each method
and scored by L2P (normalized by the training takes' own spread), position error, NPSS and foot skate, beside the
zero-velocity and linear-interpolation baselines. Used by ``experiments/inbetween/`` and the tests; the package
writes transitions, this judges them."""

from __future__ import annotations

import numpy as np

from chorjax.errors import UserError
from chorjax.evaluation.metrics import foot_skate, l2p, npss, position_error
from chorjax.families.inbetween import inbetweening as ib

BENCHMARK_LENGTHS = (5, 15, 30, 45)  # the LaFAN1 protocol's transition lengths
BENCHMARK_HOP = 40  # its windows start every 40 frames
FOOT_HEIGHT = 0.1  # leg lengths above the floor from which a foot counts as off the ground (skating)


def zero_velocity(context_BxCxK, target_BxK, frames: int) -> np.ndarray:
  """The zero-velocity baseline: the last context frame held until the target."""
  return np.repeat(np.asarray(context_BxCxK)[:, -1:], frames, 1)


def linear(context_BxCxK, target_BxK, frames: int) -> np.ndarray:
  """The linear-interpolation baseline: every joint on the straight line from the last context frame."""
  alpha = (np.arange(1, frames + 1, dtype=np.float32) / (frames + 1))[None, :, None]
  last = np.asarray(context_BxCxK)[:, -1:]
  return last + alpha * (np.asarray(target_BxK)[:, None] - last)


def benchmark_windows(takes, context: int, longest: int, hop: int = BENCHMARK_HOP) -> tuple[np.ndarray, np.ndarray]:
  """Windows of ``context + longest + 1`` canonical frames every ``hop`` frames of each take, and the
  index of the take each comes from."""
  wins = ib.spans(takes, context + longest + 1, hop)
  if not wins:
    raise UserError(f"no take holds a window of {context + longest + 1} frames")
  return np.stack([w for _, w in wins]), np.array([i for i, _ in wins])


def window_std(takes, space: ib.Space, context: int, longest: int = max(BENCHMARK_LENGTHS)) -> np.ndarray:
  """``[K]`` the standard deviation of every local coordinate over the windows of ``takes`` (the training
  takes): L2P's normalization."""
  wins, _ = benchmark_windows(takes, context, longest)
  local = ib.local_windows(space, wins, context)[:, context:]
  return np.maximum(local.reshape(-1, local.shape[-1]).std(0), 1e-6).astype(np.float32)


def benchmark(methods: dict, takes, space: ib.Space, feet, context: int, std_K, lengths=BENCHMARK_LENGTHS) -> dict:
  """``{method: {length: {l2p, position_error, npss, foot_skate, foot_skate_real, arrival_step}}}`` over the
  windows of ``takes`` (canonical positions) every 40 frames: each method (``fn(context [B, C, K], target
  [B, K], frames) -> [B, frames, K]``, local poses) writes every window's transition of each length.
  ``position_error`` is in leg lengths; ``arrival_step`` is the mean joint step from the last written frame
  into the target over the takes' own mean frame-to-frame step (1 = as far as the dancer moves in a frame)."""
  wins, which = benchmark_windows(takes, context, max(lengths))
  local = ib.local_windows(space, wins, context)
  floor = np.array([np.percentile(t[:, list(feet), 1], 5) for t in takes], np.float32)[which] / space.size
  data_step = np.mean([np.linalg.norm(np.diff(t, axis=0), axis=-1).mean() for t in takes]) / space.size
  joints = lambda x: x.reshape(*x.shape[:-1], -1, 3)
  out: dict = {}
  for name, fn in methods.items():
    out[name] = {}
    for n in lengths:
      ctx, target, real = local[:, :context], local[:, context + n], local[:, context : context + n]
      pred = np.asarray(fn(ctx, target, n), np.float32)
      arrival = np.linalg.norm(joints(target[:, None] - pred[:, -1:]), axis=-1).mean()
      out[name][n] = {
        "l2p": l2p(pred, real, std_K),
        "position_error": position_error(pred, real),
        "npss": npss(pred, real),
        "foot_skate": foot_skate(joints(np.concatenate([ctx[:, -1:], pred], 1)), feet, floor, FOOT_HEIGHT),
        "foot_skate_real": foot_skate(joints(local[:, context - 1 : context + n]), feet, floor, FOOT_HEIGHT),
        "arrival_step": float(arrival / data_step),
      }
  return out
