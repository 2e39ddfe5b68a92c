"""Generation-quality metrics: pure functions of joint positions.

Positions are ``[T, J, 3]`` y-up arrays. Metrics that compare motions of different sizes first divide
lengths by the body size (root->foot plus root->head along the bones), so numbers are in body sizes
(and body sizes per second).

* movement: root-relative joint displacement over a lag (0.5 s), per 1,000-frame segment;
* jitter: the second difference of joint positions (roughness);
* foot sliding: horizontal foot speed while the foot is on the ground; PFC (EDGE);
* FID_k / Div_k: on the AIST++ kinetic features (per joint: mean horizontal and vertical kinetic
  energy and mean acceleration magnitude, over a +-2 frame sliding window). The AIST++ API computes
  the acceleration's first velocity as ``(p[t] - p[t-1] / dt)`` — the division binds to one term
  only; here it is ``(p[t] - p[t-1]) / dt``, so the acceleration is the plain second difference / dt^2;
* geometric features: yes/no relations of a pose (``GEOMETRIC_FEATURES``), for FID_g / Div_g;
* novelty: distance from each generated window to its nearest training window.

``chorjax.evaluation.scoring`` turns these into the numbers ``chorjax eval`` and ``chorjax metrics`` report.
"""

from __future__ import annotations

import itertools

import numpy as np

from chorjax.data.motion import Skeleton, chain_length, mean_bone_lengths


def body_size(pos_TxJx3, skeleton: Skeleton) -> float:
  """Root->first foot plus root->highest end joint, along the bones (mean bone lengths)."""
  length = mean_bone_lengths(pos_TxJx3, skeleton)
  ends = skeleton.end_joints or tuple(range(skeleton.num_joints))
  head = max(ends, key=lambda j: pos_TxJx3[:, j, 1].mean())
  foot = skeleton.feet[0] if skeleton.feet else min(ends, key=lambda j: pos_TxJx3[:, j, 1].mean())
  return float(chain_length(length, skeleton, foot) + chain_length(length, skeleton, head))


def joint_speed(pos_TxJx3) -> np.ndarray:
  """``[T-1]`` mean over joints of the frame-to-frame displacement."""
  return np.linalg.norm(np.diff(pos_TxJx3, axis=0), axis=-1).mean(-1)


def root_travel(pos_TxJx3, root: int) -> np.ndarray:
  """``[T-1]``: the root's path length per frame (``root_travel`` in eval is its mean / the reference's)."""
  return np.linalg.norm(np.diff(pos_TxJx3[:, root], axis=0), axis=-1)


def pooled_speed(takes) -> float:
  """Mean joint speed per frame of ``takes``, every frame counted once (a long take weighs more): the
  ``speed`` divisor of ``chorjax eval`` and what calibration matches."""
  return float(np.mean(np.concatenate([joint_speed(t) for t in takes])))


def pooled_root_travel(takes, root: int) -> float:
  """The root's mean path length per frame over ``takes``, every frame counted once (``root_travel``'s
  divisor, as :func:`pooled_speed`)."""
  return float(np.mean(np.concatenate([root_travel(t, root) for t in takes])))


def speed_ratio(pos_TxJx3, data_speed: float) -> float:
  """Mean frame-to-frame joint speed / the data's. Not a measure of freezing: trembling in place is
  fast; see :func:`displacement`."""
  return float(joint_speed(pos_TxJx3).mean() / data_speed)


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


def airborne(pos_TxJx3, skeleton: Skeleton, size: float, height: float = 0.1) -> float:
  """The fraction of frames with every foot more than ``height`` body sizes above the floor (the 5th
  percentile of the lowest foot's height): a dancer who floats, or jumps (real dance rarely is)."""
  feet = np.asarray(skeleton.feet)
  lowest = np.asarray(pos_TxJx3)[:, feet, 1].min(-1) / size
  return float(np.mean(lowest > np.percentile(lowest, 5) + height))


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


# ---------------------------------------------------------------- movement and jitter (per segment)


def segments(pos_TxJx3, length: int = 1000) -> list[np.ndarray]:
  """Consecutive ``length``-frame segments (the whole motion if shorter; a short tail joins the last)."""
  n = max(len(pos_TxJx3) // length, 1)
  bounds = [i * length for i in range(n)] + [len(pos_TxJx3)]
  return [pos_TxJx3[a:b] for a, b in itertools.pairwise(bounds)]


def displacement(pos_TxJx3, root: int, lag: int) -> float:
  """Mean root-relative joint displacement over ``lag`` frames (how far the limbs travel in that time).

  Trembling in place moves joints back and forth around one pose: over half a second they end up
  where they were, so this stays low where the frame-to-frame speed does not.
  """
  rel = np.asarray(pos_TxJx3, np.float64) - np.asarray(pos_TxJx3, np.float64)[:, root : root + 1]
  if len(rel) <= lag:
    return 0.0
  return float(np.linalg.norm(rel[lag:] - rel[:-lag], axis=-1).mean())


def roughness(pos_TxJx3) -> float:
  """Mean magnitude of the second difference of joint positions (length per frame^2): jitter."""
  p = np.asarray(pos_TxJx3, np.float64)
  if len(p) < 3:
    return 0.0
  return float(np.linalg.norm(p[2:] - 2 * p[1:-1] + p[:-2], axis=-1).mean())


def reference_rates(takes, root: int, lag: int) -> tuple[float, float]:
  """``(displacement, roughness)`` of real takes, pooled over their frames (the divisors)."""
  weights = [len(t) for t in takes]
  disp = np.average([displacement(t, root, lag) for t in takes], weights=weights)
  rough = np.average([roughness(t) for t in takes], weights=weights)
  return float(disp), float(rough)


def movement_curve(pos_TxJx3, root: int, lag: int, reference: float, length: int = 1000) -> np.ndarray:
  """Per consecutive segment: the displacement over ``lag`` frames / the reference data's."""
  return np.array([displacement(s, root, lag) / reference for s in segments(pos_TxJx3, length)])


def jitter_curve(pos_TxJx3, reference: float, length: int = 1000) -> np.ndarray:
  """Per consecutive segment: the roughness / the reference data's."""
  return np.array([roughness(s) / reference for s in segments(pos_TxJx3, length)])


# ---------------------------------------------------------------- geometric (relational) pose features

# Each is a yes/no question about one frame, in the spirit of the AIST++ "manual" features; a
# window's feature vector is the fraction of its frames for which each answer is yes. Lengths are in
# body sizes, directions in the dancer's own frame (forward = up x the right-to-left hip axis).
GEOMETRIC_FEATURES = (
  "left foot in front of the right",
  "right foot in front of the left",
  "left hand above the head",
  "right hand above the head",
  "left hand above the left shoulder",
  "right hand above the right shoulder",
  "left knee bent (< 150 degrees)",
  "right knee bent (< 150 degrees)",
  "left elbow bent (< 120 degrees)",
  "right elbow bent (< 120 degrees)",
  "left foot raised (> 0.1 above the floor)",
  "right foot raised (> 0.1 above the floor)",
  "hands far apart (> 0.6)",
  "left hand in front of the chest (> 0.2)",
  "right hand in front of the chest (> 0.2)",
  "crouched (pelvis < 0.38 above the floor)",
  "feet wide apart (> 0.25)",
  "torso leaning (> 20 degrees from vertical)",
)


def _angle(a, b, c):
  """The angle at ``b`` (degrees) of the triangle a-b-c, per frame."""
  u, v = a - b, c - b
  cos = (u * v).sum(-1) / np.maximum(np.linalg.norm(u, axis=-1) * np.linalg.norm(v, axis=-1), 1e-9)
  return np.degrees(np.arccos(np.clip(cos, -1, 1)))


def geometric_features(pos_TxJx3, skeleton: Skeleton, size: float) -> np.ndarray:
  """``[T, F]`` booleans (as 0/1) of ``GEOMETRIC_FEATURES`` for y-up positions of an mpii16 skeleton; a stack
  of motions ``[..., T, J, 3]`` gives ``[..., T, F]``, each with its own floor, as one at a time would."""
  j = {n: i for i, n in enumerate(skeleton.joint_names)}
  p = np.asarray(pos_TxJx3, np.float64) / size
  at = lambda name: p[..., j[name], :]
  lateral = at("left_hip") - at("right_hip")
  lateral[..., 1] = 0
  lateral /= np.maximum(np.linalg.norm(lateral, axis=-1, keepdims=True), 1e-9)
  forward = np.cross(lateral, [0.0, 1.0, 0.0])  # left x up: the way the chest faces (y-up, right-handed)
  floor = np.percentile(np.minimum(at("left_foot")[..., 1], at("right_foot")[..., 1]), 5, axis=-1, keepdims=True)
  ahead = lambda v: (v * forward).sum(-1)
  torso = at("thorax") - at("pelvis")
  lean = np.degrees(np.arccos(np.clip(torso[..., 1] / np.maximum(np.linalg.norm(torso, axis=-1), 1e-9), -1, 1)))
  answers = [
    ahead(at("left_foot") - at("right_foot")) > 0.05,
    ahead(at("right_foot") - at("left_foot")) > 0.05,
    at("left_hand")[..., 1] > at("head_top")[..., 1],
    at("right_hand")[..., 1] > at("head_top")[..., 1],
    at("left_hand")[..., 1] > at("left_shoulder")[..., 1],
    at("right_hand")[..., 1] > at("right_shoulder")[..., 1],
    _angle(at("left_hip"), at("left_knee"), at("left_foot")) < 150,
    _angle(at("right_hip"), at("right_knee"), at("right_foot")) < 150,
    _angle(at("left_shoulder"), at("left_elbow"), at("left_hand")) < 120,
    _angle(at("right_shoulder"), at("right_elbow"), at("right_hand")) < 120,
    at("left_foot")[..., 1] - floor > 0.1,
    at("right_foot")[..., 1] - floor > 0.1,
    np.linalg.norm(at("left_hand") - at("right_hand"), axis=-1) > 0.6,
    ahead(at("left_hand") - at("thorax")) > 0.2,
    ahead(at("right_hand") - at("thorax")) > 0.2,
    at("pelvis")[..., 1] - floor < 0.38,
    np.abs(((at("left_foot") - at("right_foot")) * lateral).sum(-1)) > 0.25,
    lean > 20,
  ]
  return np.stack(answers, -1).astype(np.float64)


# ---------------------------------------------------------------- physical foot contact (EDGE)


def pfc(pos_TxJx3, skeleton: Skeleton, fps: float, size: float) -> float:
  """Physical foot contact score (EDGE, Tseng et al. 2023); lower is more plausible.

  Per frame: the root's acceleration (its upward part clamped at 0: gravity may pull the body down
  with both feet off the floor) divided by its largest value in the motion, times the horizontal
  speed of the left foot and of the right foot (body sizes per second); averaged over frames. A body
  that accelerates must push off a foot that stays put.
  """
  p = np.asarray(pos_TxJx3, np.float64) / size
  root = p[:, skeleton.root]
  acc = np.diff(root, 2, axis=0) * fps**2
  acc[:, 1] = np.maximum(acc[:, 1], 0)
  a = np.linalg.norm(acc, axis=-1)
  a = a / max(a.max(), 1e-12)
  feet = p[:, list(skeleton.feet[:2])]
  v = np.linalg.norm(np.diff(feet[..., [0, 2]], axis=0), axis=-1)[1:] * fps  # [T-2, 2]
  return float(np.mean(a * v[:, 0] * v[:, 1]))


# ---------------------------------------------------------------- transitions (in-betweening)


def l2p(pred_NxTxK, real_NxTxK, std_K) -> float:
  """LaFAN1's L2P: the mean over frames of the L2 norm of the position error, every coordinate divided by
  its standard deviation over the training windows (``std_K``; the mean cancels in the difference)."""
  return float(np.linalg.norm((np.asarray(pred_NxTxK) - real_NxTxK) / std_K, axis=-1).mean())


def position_error(pred_NxTxK, real_NxTxK) -> float:
  """Mean joint distance between written and real frames (flat ``[..., 3J]`` poses, in their units)."""
  diff = (np.asarray(pred_NxTxK) - real_NxTxK).reshape(*np.shape(pred_NxTxK)[:-1], -1, 3)
  return float(np.linalg.norm(diff, axis=-1).mean())


def npss(pred_NxTxF, real_NxTxF) -> float:
  """Normalized power spectrum similarity (Gopalakrishnan et al. 2019): per sequence and feature, the earth
  mover's distance between the real and written normalized power spectra over time, averaged with the
  real sequences' power as weights. 0 = the same frequency content."""
  power = lambda x: np.square(np.abs(np.fft.fft(np.asarray(x, np.float64), axis=1)))
  p_real, p_pred = power(real_NxTxF), power(pred_NxTxF)
  total_real, total_pred = p_real.sum(1), p_pred.sum(1)
  cdf = lambda p, total: np.cumsum(p / np.maximum(total[:, None], 1e-12), axis=1)
  emd = np.abs(cdf(p_pred, total_pred) - cdf(p_real, total_real)).sum(1)
  return float(np.average(emd, weights=total_real + 1e-12))


def foot_skate(frames_NxTxJx3, feet, floor_N, height: float) -> float:
  """Mean horizontal foot speed (units per frame) weighted by nearness to the floor, as Zhang et al. 2018
  and Tang et al. 2022 measure skating: each foot's step times ``clip(2 - 2^(h / height), 0, 1)``, ``h``
  its height above ``floor`` (1 on the floor, 0 from ``height`` up)."""
  f = np.asarray(frames_NxTxJx3)[:, :, list(feet)]
  h = f[:, 1:, :, 1] - np.asarray(floor_N)[:, None, None]
  weight = np.clip(2.0 - np.power(2.0, np.maximum(h, 0.0) / height), 0.0, 1.0)
  step = np.linalg.norm(np.diff(f, axis=1)[..., [0, 2]], axis=-1)
  return float((step * weight).mean())
