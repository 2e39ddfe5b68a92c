"""Generation-quality metrics: pure functions of joint positions.

Positions are ``[T, J, 3]`` y-up arrays. Metrics that compare motions of different sizes first divide
lengths by the body size (root->foot plus root->head along the bones), so numbers are in body sizes
(and body sizes per second).

* freezing: mean joint speed in consecutive windows / the data's mean joint speed;
* anatomy: per-bone length coefficient of variation;
* foot sliding: horizontal foot speed while the foot is on the ground;
* FID_k / Div_k: on the AIST++ kinetic features (per joint: mean horizontal and vertical kinetic
  energy and mean acceleration magnitude, over a +-2 frame sliding window). The AIST++ API computes
  the acceleration's first velocity as ``(p[t] - p[t-1] / dt)`` — the division binds to one term
  only; here it is ``(p[t] - p[t-1]) / dt``, so the acceleration is the plain second difference / dt^2;
* novelty: distance from each generated window to its nearest training window.
"""

from __future__ import annotations

import numpy as np

from chorjax.data.motion import Skeleton, bone_length_cv, bone_lengths


def body_size(pos_TxJx3, skeleton: Skeleton) -> float:
  """Root->first foot plus root->highest end joint, along the bones (mean bone lengths)."""
  children = [c for _, c in skeleton.bones]
  length = dict(zip(children, bone_lengths(pos_TxJx3, skeleton).mean(0)))

  def chain(j):
    total = 0.0
    while skeleton.parents[j] >= 0:
      total, j = total + length[j], skeleton.parents[j]
    return total

  ends = skeleton.end_joints or tuple(range(skeleton.num_joints))
  head = max(ends, key=lambda j: pos_TxJx3[:, j, 1].mean())
  foot = skeleton.feet[0] if skeleton.feet else min(ends, key=lambda j: pos_TxJx3[:, j, 1].mean())
  return float(chain(foot) + chain(head))


def joint_speed(pos_TxJx3) -> np.ndarray:
  """``[T-1]`` mean over joints of the frame-to-frame displacement."""
  return np.linalg.norm(np.diff(pos_TxJx3, axis=0), axis=-1).mean(-1)


def freeze_curve(pos_TxJx3, data_speed: float, window: int = 100) -> np.ndarray:
  """Mean joint speed per consecutive window, divided by the data's mean joint speed."""
  s = joint_speed(pos_TxJx3)
  n = len(s) // window
  return s[: n * window].reshape(n, window).mean(-1) / data_speed


def freeze_ratio(pos_TxJx3, data_speed: float) -> float:
  return float(joint_speed(pos_TxJx3).mean() / data_speed)


def bone_cv(pos_TxJx3, skeleton: Skeleton) -> dict:
  cv = bone_length_cv(np.asarray(pos_TxJx3), skeleton)
  return {"median": float(np.median(cv)), "max": float(cv.max())}


def foot_sliding(
  pos_TxJx3, skeleton: Skeleton, fps: float, size: float, height_tol: float = 0.05, speed_tol: float = 1.0
) -> float:
  """Mean horizontal foot speed (body sizes / s) over frames where a foot is on the ground.

  A foot is on the ground when it is within ``height_tol`` body sizes of the floor (the 5th
  percentile of foot heights) and moves slower than ``speed_tol`` body sizes per second.
  """
  feet = np.asarray(skeleton.feet)
  f = np.asarray(pos_TxJx3)[:, feet] / size
  floor = np.percentile(f[..., 1], 5)
  vel = np.diff(f, axis=0) * fps
  speed, horizontal = np.linalg.norm(vel, axis=-1), np.linalg.norm(vel[..., [0, 2]], axis=-1)
  contact = (f[1:, :, 1] < floor + height_tol) & (speed < speed_tol)
  return float(horizontal[contact].mean()) if contact.any() else 0.0


# ---------------------------------------------------------------- kinetic features, FID, diversity


def _window_mean(x_TxN, first: int, last: int, w: int) -> np.ndarray:
  """For every t, the mean of rows max(first, t-w)..min(last, t+w) of x (a centred sliding window)."""
  t = np.arange(x_TxN.shape[0])
  lo, hi = np.maximum(first, t - w), np.minimum(last, t + w)
  c = np.concatenate([np.zeros((1,) + x_TxN.shape[1:]), np.cumsum(x_TxN, axis=0)])
  count = np.maximum(hi - lo + 1, 1)
  s = c[np.maximum(hi + 1, lo)] - c[lo]
  return s / count.reshape((-1,) + (1,) * (x_TxN.ndim - 1))


def kinetic_features(pos_TxJx3, fps: float, window: int = 2) -> np.ndarray:
  """``[3J]``: per joint, mean horizontal and vertical kinetic energy and mean acceleration magnitude."""
  p = np.asarray(pos_TxJx3, np.float64)
  t, dt = p.shape[0], 1.0 / fps
  d = np.concatenate([np.zeros_like(p[:1]), np.diff(p, axis=0)])  # d[k] = p[k] - p[k-1], k >= 1
  v = _window_mean(d, 1, t - 1, window)[1:] / dt  # average velocity at frames 1..T-1
  ke_h = (v[..., 0] ** 2 + v[..., 2] ** 2).mean(0)
  ke_v = (v[..., 1] ** 2).mean(0)
  a = np.zeros_like(p)
  a[1:-1] = (p[2:] - 2 * p[1:-1] + p[:-2]) / dt**2  # a[k] uses k-1, k, k+1
  acc = _window_mean(a, 1, t - 2, window)[1:]
  ee = np.linalg.norm(acc, axis=-1).mean(0)
  return np.stack([ke_h, ke_v, ee], axis=-1).reshape(-1).astype(np.float64)


def _sqrtm_psd(m):
  w, v = np.linalg.eigh((m + m.T) / 2)
  return (v * np.sqrt(np.clip(w, 0, None))) @ v.T


def frechet_distance(feats_a, feats_b) -> float:
  """FID between two sets of feature vectors (rows)."""
  mu_a, mu_b = feats_a.mean(0), feats_b.mean(0)
  sa, sb = np.cov(feats_a, rowvar=False), np.cov(feats_b, rowvar=False)
  root_a = _sqrtm_psd(sa)
  cross = np.sqrt(np.clip(np.linalg.eigvalsh(root_a @ sb @ root_a), 0, None)).sum()
  return float(np.sum((mu_a - mu_b) ** 2) + np.trace(sa) + np.trace(sb) - 2 * cross)


def diversity(feats) -> float:
  """Mean pairwise Euclidean distance between feature vectors."""
  feats = np.asarray(feats, np.float64)
  n = len(feats)
  sq = np.sum(feats**2, 1)
  d = np.sqrt(np.maximum(sq[:, None] + sq[None] - 2 * feats @ feats.T, 0))
  return float(d.sum() / (n * (n - 1)))


def fid_k(real_feats, gen_feats) -> dict:
  """FID_k and Div_k with features normalized by the real set's statistics (as in Bailando)."""
  mean, std = real_feats.mean(0), real_feats.std(0) + 1e-10
  r, g = (real_feats - mean) / std, (gen_feats - mean) / std
  return {"fid_k": frechet_distance(r, g), "div_k": diversity(g), "real_div_k": diversity(r)}


def windows(pos_TxJx3, length: int, hop: int) -> np.ndarray:
  """``[N, length, J, 3]`` windows of a motion."""
  starts = range(0, pos_TxJx3.shape[0] - length + 1, hop)
  return (
    np.stack([pos_TxJx3[s : s + length] for s in starts])
    if len(starts)
    else np.zeros((0, length) + pos_TxJx3.shape[1:])
  )


# ---------------------------------------------------------------- novelty


def _pose_vectors(wins_NxLxJx3, root: int) -> np.ndarray:
  wins = np.asarray(wins_NxLxJx3, np.float64)  # float64: the distance expansion below cancels heavily
  rel = wins - wins[:, :, root : root + 1]  # where the dancer stands does not matter
  return rel.reshape(len(rel), -1)


def novelty(gen_windows, train_windows, root: int) -> float:
  """Mean RMS joint distance from each generated window to its nearest training window."""
  g, t = _pose_vectors(gen_windows, root), _pose_vectors(train_windows, root)
  d2 = np.sum(g**2, 1)[:, None] + np.sum(t**2, 1)[None] - 2 * g @ t.T
  per_point = gen_windows.shape[1] * gen_windows.shape[2]
  return float(np.sqrt(np.maximum(d2.min(1), 0) / per_point).mean())
