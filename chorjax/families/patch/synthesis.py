"""Multi-scale nearest-patch synthesis: a new dance recombined from the pieces of the training takes.

The method of GenMM (Li et al., SIGGRAPH 2023), on the run's normalized features: the takes are resampled to a
pyramid of scales (``patch.factor`` apart, the coarsest ``patch.coarsest`` of the finest's length); at the
coarsest a dance starts as random stretches of the takes end to end; at each scale, ``patch.iterations``
times, every window of ``patch.size`` frames of the dance is replaced by its nearest window of the takes and
the overlapping replacements are averaged frame by frame; the result, stretched to the next finer scale,
starts that scale's passes. The distance to a window of the takes is divided by ``patch.alpha`` plus that
window's nearest distance to any window of the dance (completeness), so the dance uses the takes' windows
widely instead of the few that match best. No training, no network: numpy on the host.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

CHUNK = 2048  # query windows per distance block: [CHUNK, windows of the takes] float32 at a time


def resample(x_TxD: np.ndarray, length: int) -> np.ndarray:
  """``x`` stretched or squeezed in time to ``length`` frames (linear interpolation, ends kept)."""
  t = len(x_TxD)
  if length == t:
    return x_TxD
  at = np.linspace(0.0, t - 1, length)
  lo = np.floor(at).astype(int)
  hi = np.minimum(lo + 1, t - 1)
  w = (at - lo)[:, None].astype(x_TxD.dtype)
  return (1 - w) * x_TxD[lo] + w * x_TxD[hi]


def windows(x_TxD: np.ndarray, size: int) -> np.ndarray:
  """Every window of ``size`` frames of ``x``: ``[T - size + 1, size, D]`` (a view)."""
  return np.moveaxis(sliding_window_view(x_TxD, size, axis=0), -1, 1)


def nearest(queries_NxF: np.ndarray, keys_KxF: np.ndarray, alpha: float) -> np.ndarray:
  """For each query, the index of the key with the least squared distance over ``alpha`` + that key's least
  distance to any query ``[N]`` (in blocks of ``CHUNK`` queries)."""
  kk = np.einsum("kf,kf->k", keys_KxF, keys_KxF)

  def distances(block):
    qq = np.einsum("nf,nf->n", block, block)
    return np.maximum(qq[:, None] + kk[None] - 2.0 * block @ keys_KxF.T, 0.0)

  blocks = [queries_NxF[i : i + CHUNK] for i in range(0, len(queries_NxF), CHUNK)]
  least = np.min([distances(b).min(0) for b in blocks], axis=0)
  return np.concatenate([np.argmin(distances(b) / (alpha + least)[None], axis=1) for b in blocks])


def blend(chosen_NxSxD: np.ndarray, length: int) -> np.ndarray:
  """Windows placed at every start ``0..N-1`` of a ``length``-frame sequence, overlaps averaged: ``[length, D]``."""
  n, size, d = chosen_NxSxD.shape
  total = np.zeros((length, d), chosen_NxSxD.dtype)
  count = np.zeros((length, 1), chosen_NxSxD.dtype)
  for k in range(size):
    total[k : k + n] += chosen_NxSxD[:, k]
    count[k : k + n] += 1
  return total / count


def levels(cfg) -> int:
  """How many scales the pyramid has: the coarsest at least ``cfg.coarsest`` of the finest's length."""
  return 1 + math.floor(math.log(cfg.coarsest) / math.log(cfg.factor) + 1e-9)


def _start(takes: list[np.ndarray], length: int, size: int, rng: np.random.Generator) -> np.ndarray:
  """Random stretches (4 windows long, or a whole shorter take) of random takes, end to end, ``length`` frames."""
  pieces, have = [], 0
  while have < length:
    take = takes[rng.integers(len(takes))]
    n = min(4 * size, len(take))
    at = rng.integers(len(take) - n + 1)
    pieces.append(take[at : at + n])
    have += n
  return np.concatenate(pieces)[:length]


def synthesize(takes: list[np.ndarray], frames: int, cfg, rng: np.random.Generator) -> np.ndarray:
  """A ``frames``-frame dance ``[frames, D]`` recombined from ``takes`` (each ``[T, D]``, at least ``cfg.size``
  frames) with ``cfg`` (``[patch]``'s keys), drawn from ``rng``."""
  size, dance = cfg.size, None
  for level in reversed(range(levels(cfg))):
    scale = cfg.factor**level
    scaled = [resample(t, round(len(t) * scale)) for t in takes]
    scaled = [t for t in scaled if len(t) >= size] or [resample(t, size) for t in takes]
    length = max(round(frames * scale), size)
    dance = _start(scaled, length, size, rng) if dance is None else resample(dance, length)
    keys = np.concatenate([windows(t, size) for t in scaled])
    flat = keys.reshape(len(keys), -1)
    for _ in range(cfg.iterations):
      queries = np.ascontiguousarray(windows(dance, size)).reshape(length - size + 1, -1)
      dance = blend(keys[nearest(queries, flat, cfg.alpha)], length)
  assert dance is not None
  return dance[:frames]
