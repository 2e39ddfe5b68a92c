"""The single-take measures: how a dance drawn from one take (or a few) uses that take, as the single-motion
papers judge it (GANimator, SIGGRAPH 2022; SinMDM and GenMM report the same four).

Every measure compares frames through one per-frame cost: the L2 distance between two poses, each its joints
relative to the root's point on the floor in the facing frame (heading removed, height kept), in body sizes.
A piece of ``n`` frames is compared with a piece of the take frame by frame, in order; its cost is the mean
of the ``n`` frames' costs.

* ``coverage``: the share of the take's ``COVERAGE_FRAMES``-frame windows (every start) that some window of the
  sample comes within ``COVERAGE_THRESHOLD`` of, averaged over samples: how much of the take a sample dances
  (1 = all of it); ``coverage_together``: the same for all the samples together.
* ``global_diversity``: the sample cut into pieces of at least ``GLOBAL_FRAMES`` frames, each matched to a piece
  of the take, the cut that costs least (dynamic programming), its mean per-frame cost: 0 for a sample that
  replays the take in long pieces, higher the more it recombines.
* ``local_diversity``: for every ``LOCAL_FRAMES``-frame window of the sample, the cost of the take's window
  nearest to it, averaged: how far the sample strays from the take at the scale of a step.
* ``inter_diversity``: ``global_diversity`` of each sample against each other sample (their first
  ``INTER_FRAMES`` frames), averaged over pairs: how different two samples are (0 = the same dance; needs two).

The papers measure joint rotations; chorjax measures positions, so the threshold is its own: 0.15 body sizes
(L2 over the joints) on average over the window: a take danced a little faster or slower comes within it,
another take of the dancer does not (the figures: ``docs/perf-notes.md``). Covered are the take's moves, not
another choreography.
"""

from __future__ import annotations

import numpy as np

from chorjax.data.features import hips
from chorjax.data.motion import Skeleton
from chorjax.errors import UserError

COVERAGE_FRAMES = 30
COVERAGE_THRESHOLD = 0.15
GLOBAL_FRAMES = 30
LOCAL_FRAMES = 15
INTER_FRAMES = 1000  # inter_diversity compares the samples' first 1,000 frames (10,000 x 10,000 costs: 800 MB)
KEYS = ("coverage", "coverage_together", "global_diversity", "local_diversity", "inter_diversity")  # single_take's
MAX_COST_CELLS = 200_000_000  # frames of the samples x frames of the takes one measure may compare


def facing_poses(pos_TxJx3, skeleton: Skeleton, size: float) -> np.ndarray:
  """``[T, 3J]``: each frame's joints relative to the root's point on the floor, turned so that the body faces
  +z, in body sizes (``size``): what the single-take costs compare."""
  p = np.asarray(pos_TxJx3, np.float64)
  left, right = hips(skeleton)
  across = p[:, left] - p[:, right]
  angle = np.arctan2(-across[:, 2], across[:, 0])  # transforms.heading, in numpy
  rel = p - p[:, skeleton.root : skeleton.root + 1] * np.array([1.0, 0.0, 1.0])
  c, s = np.cos(-angle)[:, None], np.sin(-angle)[:, None]
  x, y, z = rel[..., 0], rel[..., 1], rel[..., 2]
  turned = np.stack([c * x + s * z, y, -s * x + c * z], -1)
  return (turned / size).reshape(len(p), -1)


def frame_costs(a_TxF, b_UxF) -> np.ndarray:
  """``[T, U]``: the L2 distance between every frame of ``a`` and every frame of ``b``."""
  sq = (a_TxF**2).sum(1)[:, None] + (b_UxF**2).sum(1)[None] - 2.0 * a_TxF @ b_UxF.T
  return np.sqrt(np.maximum(sq, 0.0))


def window_costs(cost_TxU, n: int) -> np.ndarray:
  """``[T - n + 1, U - n + 1]``: the mean cost of each ``n``-frame window of the rows against each of the
  columns, frame by frame along the diagonal."""
  rows, cols = cost_TxU.shape[0] - n + 1, cost_TxU.shape[1] - n + 1
  total = np.zeros((rows, cols))
  for d in range(n):
    total += cost_TxU[d : d + rows, d : d + cols]
  return total / n


def patched_cost(cost_TxU, shortest: int, starts=(0,)) -> float:
  """The least total cost of cutting the rows (a sample's frames) into pieces of at least ``shortest`` frames,
  each matched frame by frame to consecutive columns (a take's frames) that do not cross a take's start
  (``starts``: the column where each take begins), divided by the rows: ``global_diversity``. Dynamic
  programming over (column, the piece's length so far, capped at ``shortest``)."""
  t, u = cost_TxU.shape
  if t < shortest or u < shortest:
    raise UserError(f"single-take measures: pieces of {shortest} frames need that many frames in each motion")
  continues = np.ones(u, bool)  # column j may follow column j - 1 within one piece
  continues[0] = False
  continues[[s for s in starts if 0 < s < u]] = False
  best = np.full((u, shortest), np.inf)
  best[:, 0] = cost_TxU[0]
  for i in range(1, t):
    ended = best[:, -1].min()  # a piece long enough ends; the next starts anywhere
    nxt = np.full((u, shortest), np.inf)
    nxt[:, 0] = ended + cost_TxU[i]
    grown = np.full((u, shortest), np.inf)
    grown[1:, 1:] = best[:-1, :-1]  # one frame longer along the diagonal
    grown[1:, -1] = np.minimum(grown[1:, -1], best[:-1, -1])  # a long piece stays long
    grown[~continues] = np.inf
    nxt = np.minimum(nxt, grown + cost_TxU[i][:, None])
    best = nxt
  return float(best[:, -1].min() / t)


def single_take(samples, takes, skeleton: Skeleton, size: float) -> dict:
  """The four measures of ``samples`` (``[T, J, 3]`` each, y-up) against ``takes`` (the take or takes they
  were drawn from, same form); ``size``: the body size that makes costs unitless. ``inter_diversity`` is None
  for one sample."""
  poses = [facing_poses(s, skeleton, size) for s in samples]
  take_poses = [facing_poses(t, skeleton, size) for t in takes]
  whole = np.concatenate(take_poses)
  starts = np.cumsum([0] + [len(t) for t in take_poses[:-1]])
  longest = max(COVERAGE_FRAMES, GLOBAL_FRAMES, LOCAL_FRAMES)
  if any(len(p) < longest for p in [*poses, *take_poses]):
    raise UserError(f"single-take measures: every sample and take needs at least {longest} frames")
  cells = sum(len(p) for p in poses) * len(whole)
  if cells > MAX_COST_CELLS:
    raise UserError(
      f"single-take measures: {cells:,} frame pairs to compare, more than {MAX_COST_CELLS:,}; score fewer or "
      "shorter samples against a shorter take"
    )
  covered, local, patched = [], [], []
  for p in poses:
    costs = frame_costs(p, whole)
    per_take = np.split(costs, starts[1:], axis=1)
    covered.append(np.concatenate([window_costs(c, COVERAGE_FRAMES).min(0) for c in per_take]))
    local.append(np.min([window_costs(c, LOCAL_FRAMES).min(1) for c in per_take], 0).mean())
    patched.append(patched_cost(costs, GLOBAL_FRAMES, starts))
  take_windows = np.min(covered, 0)  # each take window: the nearest any sample comes
  heads = [p[:INTER_FRAMES] for p in poses]
  pairs = [patched_cost(frame_costs(a, b), GLOBAL_FRAMES) for i, a in enumerate(heads) for b in heads[i + 1 :]]
  return {
    "coverage": float(np.mean([np.mean(c < COVERAGE_THRESHOLD) for c in covered])),
    "coverage_together": float(np.mean(take_windows < COVERAGE_THRESHOLD)),
    "global_diversity": float(np.mean(patched)),
    "local_diversity": float(np.mean(local)),
    "inter_diversity": float(np.mean(pairs)) if pairs else None,
  }
