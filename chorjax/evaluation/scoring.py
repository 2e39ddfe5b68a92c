"""One ruler for any motion: the generation metrics of ``chorjax eval`` and ``chorjax metrics``.

``score(motions, reference, ...)`` measures motions (generated samples, another system's output, or a
real take) against real reference takes of the same skeleton. All positions are y-up, in the data's
units; lengths are divided by the reference's body size where sizes matter.

Keys (a value, or ``{"mean", "sd"}`` over several motions or reference splits):

* ``movement_first``, ``movement_last``, ``movement_min``, ``movement_max``: per consecutive segment of
  ``segment_frames`` frames (``segment``, default 1,000; the shortest motion's length if that is shorter),
  the mean root-relative joint displacement over 0.5 s divided by the reference's; 1 = moves as much as
  the data, trembling in place -> 0.
* ``jitter``, ``jitter_max``: mean magnitude of the second difference of joint positions / the
  reference's, over the whole motion and in its roughest segment.
* ``per_motion``: per motion (in order), the values that bars are set on one sample at a time:
  ``movement_min``, ``movement_max``, ``jitter_max`` and ``root_step_max`` (the keys above hold their mean
  and sd).
* ``bone_cv_mean``, ``bone_cv_max`` (and ``bone_cv_median``): per-bone length CV, mean and max over bones.
* ``root_step_max``: the largest per-frame root displacement / the reference's largest (> 1.5: teleports).
* ``fid_k`` / ``fid_g``: Frechet distances on kinetic / geometric window features, normalized by the
  statistics of all reference windows (Bailando; the geometric features' std floored at 0.05).
  ``fid_k_real`` / ``fid_g_real``: the same figure between two disjoint halves of the real
  reference, so a model can be read against the data's own spread. Resampling: each of ``splits``
  rounds splits the reference TAKES in two random halves A and B (a single take: its first and
  second half in time); the motions' windows and B's windows are subsampled to the same count n =
  min(|motions|, |B|); ``fid_*`` = FID(A, motions_n) and ``fid_*_real`` = FID(A, B_n). Windows are
  ``window`` frames (60 = 2 s at 30 fps), reference hop ``window // 4``, motion hop ``window // 2``.
  ``fid_k_train`` / ``fid_g_train`` (when the reference is held-out takes and the training takes are
  given): the same figure for the run's TRAINING takes scored as if they were a sample against the
  held-out ones, with the same splits: as close as another stretch of real dance by this dancer gets. The
  honest bar for a model judged on takes it never saw (None otherwise). ``movement_min_train`` /
  ``movement_max_train`` (likewise): the calmest and the busiest ``segment``-frame segment of the training
  takes (a shorter take is one segment): how far real dance by this dancer strays from the held-out takes'
  movement (cmu94's takes: 0.66-1.27 of its two held-out ones').
* ``speed``: mean joint speed per frame / the reference's (trembling is fast too: read it with
  ``jitter``); ``root_travel``: the root's path length per frame / the reference's (a dancer who stays on
  one spot -> 0).
* ``div_k`` / ``div_g``: mean pairwise distance between the motions' normalized window features.
* ``pfc``: EDGE's physical foot contact score; ``foot_sliding``: horizontal foot speed in contact
  (both in body sizes per second; ``data_pfc`` and ``data_foot_sliding`` are the reference's).
* ``airborne``: the fraction of frames with every foot more than 0.1 body sizes above the floor (floating,
  or a jump); ``airborne_real``: the reference takes' own (real dance: under 1%).
* ``novelty``: RMS joint distance (body sizes) from each motion window to its nearest window of the
  training takes (``chorjax metrics``: of the reference); ``novelty_real``: the same for real takes
  that are not training takes (``chorjax metrics``: each reference take against the others).
* ``coverage``, ``coverage_together``, ``global_diversity``, ``local_diversity``, ``inter_diversity``: the
  single-take measures (:mod:`chorjax.evaluation.single_take`) against the training takes (``chorjax metrics``: the
  reference), where those hold at most two minutes (``SINGLE_TAKE_FRAMES``); None otherwise.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from pathlib import Path

import numpy as np

from chorjax.data import transforms
from chorjax.data.dataset import read_takes
from chorjax.data.mapping import to_mpii16
from chorjax.data.motion import Skeleton, bone_length_cv
from chorjax.errors import UserError, atomic_write, check_output, refuse_existing
from chorjax.evaluation import metrics
from chorjax.evaluation.single_take import KEYS, single_take
from chorjax.fields import suggest
from chorjax.sections import DataConfig


def spread(values) -> float | dict:
  """One value as is; several as ``{"mean", "sd"}`` (sample sd)."""
  v = np.asarray(values, np.float64).ravel()
  if len(v) == 1:
    return float(v[0])
  return {"mean": float(v.mean()), "sd": float(v.std(ddof=1))}


def mean_of(value) -> float:
  """The mean of a value written by :func:`spread`."""
  return float(value["mean"]) if isinstance(value, dict) else float(value)


@dataclasses.dataclass
class Judged:
  """What every metric reads: the motions and the reference takes (``[T, J, 3]`` each, y-up), their skeleton and
  rate, the training takes and the real takes that are not training takes where known (None otherwise), the
  options of :func:`score`, and the reference's mean body size (``size``)."""

  motions: list
  reference: list
  skeleton: Skeleton
  fps: float
  train: list | None
  unseen: list | None
  window: int
  splits: int
  segment: int
  seed: int
  size: float

  def kinetic(self, windows):
    """Windows ``[N, W, J, 3]`` -> FID_k's rows (kinetic features, in body sizes)."""
    return [metrics.kinetic_features(w / self.size, self.fps) for w in windows]

  def distribution(self, motions, features, floor: float, diversity: bool = True) -> tuple:
    """:func:`_distribution` of ``motions`` against the reference with the options."""
    return _distribution(motions, self.reference, features, self.window, self.splits, self.seed, floor, None, diversity)


@dataclasses.dataclass(frozen=True)
class Metric:
  """One metric: ``measure`` maps a :class:`Judged` to its keys (and ``per_motion`` entries, merged);
  ``printed``: the keys ``chorjax metrics`` and ``chorjax eval`` print, in order (every key is in the JSON)."""

  name: str
  printed: tuple[str, ...]
  measure: Callable[[Judged], dict]

  @property
  def summary(self) -> str:
    """The first line of ``measure``'s docstring: what the docs say of it."""
    return (self.measure.__doc__ or "").strip().splitlines()[0]


METRICS: dict[str, Metric] = {}  # by name, in the order they are printed


def metric(name: str, *printed: str):
  """Registers the decorated function as the metric ``name`` (``printed``: its keys ``chorjax metrics``
  prints). A new metric is one function and this line; ``score``, the reports and ``docs/metrics.md`` follow."""

  def register(measure: Callable[[Judged], dict]) -> Callable[[Judged], dict]:
    if name in METRICS:
      raise ValueError(f"metric {name!r} is registered twice")
    METRICS[name] = Metric(name, printed, measure)
    return measure

  return register


def _window_rows(takes, window: int, hop: int, features) -> list:
  """Each window's feature row, take by take: ``features`` maps a take's windows ``[N, W, J, 3]`` to N rows."""
  return [row for t in takes for row in features(metrics.windows(t, window, hop))]


# geometric features are fractions of a window's frames: a std below 5% of the frames is noise
GEO_STD_FLOOR = 0.05


def _pose_features(skeleton: Skeleton, size: float):
  """Windows ``[N, W, J, 3]`` (y-up) -> ``[N, F]``: the fraction of each one's frames answering yes to each pose
  question (FID_g's features), all windows at once."""
  return lambda ws: metrics.geometric_features(ws, skeleton, size).mean(-2)


def _stack(rows) -> np.ndarray:
  return np.stack(rows) if rows else np.zeros((0, 0))


def _pieces(reference) -> list:
  """What the reference is split into: its takes, or a single take's first and second half in time."""
  if len(reference) >= 2:
    return list(reference)
  t = reference[0]
  return [t[: len(t) // 2], t[len(t) // 2 :]]


def _halves(reference, rng) -> tuple:
  """Indices into :func:`_pieces` of two random halves of the takes (a single take: its two halves)."""
  if len(reference) >= 2:
    order = rng.permutation(len(reference))
    k = len(reference) // 2
    return order[:k], order[k:]
  return [0], [1]


def _reference_rows(reference, features, window: int) -> tuple:
  """``(feature rows of each of the reference's pieces, of all its windows)``: what every split draws from."""
  hop = max(window // 4, 1)
  piece_rows = [_window_rows([p], window, hop, features) for p in _pieces(reference)]
  ref_all = _stack(
    [r for rows in piece_rows for r in rows] if len(reference) >= 2 else _window_rows(reference, window, hop, features)
  )
  return piece_rows, ref_all


class TooFewWindows(UserError):
  """The reference takes (or the motions) hold too few windows for a Frechet distance."""


def _measured(keys, measure) -> dict:
  """``measure()`` (a distribution metric's dict), or each of ``keys`` None with a note (the reason
  :func:`_distribution` gives) where the reference or the motions are too short for a distribution (a single
  take's held-out tail): the other metrics still stand."""
  try:
    return measure()
  except TooFewWindows as e:
    return {**dict.fromkeys(keys), "fid_note": f"FIDs and diversities not measured: {str(e).removeprefix('--data: ')}"}


def _distribution(
  motions, reference, features, window: int, splits: int, seed: int, std_floor: float, rows=None, diversity=True
) -> tuple:
  """``(fid values, fid_real values, div, div_real)`` under the resampling scheme in the module doc.

  Features are normalized by the reference windows' mean and std, the std floored at ``std_floor``: a
  feature the reference never varies (a pose it never takes) must not divide by zero. ``rows``: the
  reference's ``_reference_rows``, where they were measured before. ``diversity=False``: the two
  diversities (up to 1,000 x 1,000 distances each) are not computed and are None.
  """
  piece_rows, ref_all = rows or _reference_rows(reference, features, window)
  gen = _stack(_window_rows(motions, window, max(window // 2, 1), features))
  mean, std = ref_all.mean(0), np.maximum(ref_all.std(0), std_floor)
  norm = lambda f: (f - mean) / std
  rng = np.random.default_rng(seed)
  fids, reals = [], []
  for _ in range(splits):
    a, b = _halves(reference, rng)
    fa, fb = (_stack([r for i in half for r in piece_rows[i]]) for half in (a, b))
    n = min(len(fb), len(gen))
    if n < 2 or len(fa) < 2:
      continue
    gen_n, fb_n = gen[rng.choice(len(gen), n, replace=False)], fb[rng.choice(len(fb), n, replace=False)]
    fids.append(metrics.frechet_distance(norm(fa), norm(gen_n)))
    reals.append(metrics.frechet_distance(norm(fa), norm(fb_n)))
  if not fids:
    raise TooFewWindows(
      f"--data: too few {window}-frame windows in the reference takes or the motions to compare distributions "
      "(longer takes, or a smaller --window)"
    )
  if not diversity:
    return fids, reals, None, None
  cap = lambda f: f[rng.choice(len(f), min(len(f), 1000), replace=False)]
  return fids, reals, metrics.diversity(norm(cap(gen))), metrics.diversity(norm(cap(ref_all)))


class PoseDistribution:
  """The geometric FID (``fid_g``) of motions against fixed reference takes over the reference's own (one half
  of its takes against the other, or a single take's halves; mean over ``splits``): what ``chorjax calibrate``
  holds a sample's poses to. The reference's windows are measured once."""

  def __init__(self, reference, skeleton: Skeleton, window: int = 60, splits: int = 4, seed: int = 0):
    self.reference, self.window, self.splits, self.seed = list(reference), window, splits, seed
    size = float(np.mean([metrics.body_size(t, skeleton) for t in self.reference]))
    self.features = _pose_features(skeleton, size)
    self.rows = _reference_rows(self.reference, self.features, window)

  def ratio(self, motions) -> float:
    """FID_g of ``motions`` (``[T, J, 3]`` each, y-up, at least ``window`` frames) / the reference's own."""
    args = (self.features, self.window, self.splits, self.seed, GEO_STD_FLOOR, self.rows)
    fids, reals, *_ = _distribution(motions, self.reference, *args, diversity=False)
    return float(np.mean(fids) / max(np.mean(reals), 1e-9))


# The metrics, in the order ``chorjax metrics`` prints them.


@metric("movement", "movement_first", "movement_last", "movement_min", "movement_max", "jitter", "jitter_max")
def movement(j: Judged) -> dict:
  """Movement over 0.5 s and jitter, segment by segment, against the reference's (and the training takes').

  With the training takes (where the reference is held-out takes), ``movement_min_train`` /
  ``movement_max_train``: the calmest and the busiest segment of real dance by this dancer, in segments of
  ``segment`` frames (a take shorter than that is one)."""
  skeleton, train = j.skeleton, j.train if j.unseen else None
  lag = max(round(0.5 * j.fps), 1)
  ref_disp, ref_rough = metrics.reference_rates(j.reference, skeleton.root, lag)
  curve = lambda m, length: metrics.movement_curve(m, skeleton.root, lag, ref_disp, length)
  real = np.concatenate([curve(t, j.segment) for t in train]) if train else None
  segment = min(j.segment, min(len(m) for m in j.motions))
  moves = [curve(m, segment) for m in j.motions]
  jitters = [metrics.jitter_curve(m, ref_rough, segment) for m in j.motions]
  each = {
    "movement_min": [float(c.min()) for c in moves],
    "movement_max": [float(c.max()) for c in moves],
    "jitter_max": [float(c.max()) for c in jitters],
  }
  return {
    "segment_frames": segment,
    "per_motion": each,
    "movement_first": spread([c[0] for c in moves]),
    "movement_last": spread([c[-1] for c in moves]),
    **{k: spread(v) for k, v in each.items()},
    "jitter": spread([metrics.roughness(m) / ref_rough for m in j.motions]),
    "movement_curve": np.mean([c for c in moves if len(c) == len(moves[0])], axis=0).tolist(),
    "movement_lag_frames": lag,
    "movement_min_train": None if real is None else float(real.min()),
    "movement_max_train": None if real is None else float(real.max()),
  }


@metric("bones", "bone_cv_mean", "bone_cv_max")
def bones(j: Judged) -> dict:
  """Each bone's length CV over a motion: mean, median and max over bones (0: rigid bones)."""
  cvs = [bone_length_cv(m, j.skeleton) for m in j.motions]
  return {
    "bone_cv_mean": spread([c.mean() for c in cvs]),
    "bone_cv_max": spread([c.max() for c in cvs]),
    "bone_cv_median": spread([np.median(c) for c in cvs]),
  }


@metric("root steps", "root_step_max")
def root_steps(j: Judged) -> dict:
  """The largest per-frame root displacement of each motion / the largest in the reference (teleports)."""
  largest = lambda p: float(np.linalg.norm(np.diff(p[:, j.skeleton.root], axis=0), axis=-1).max())
  ref = max(largest(t) for t in j.reference)
  each = [largest(m) / ref for m in j.motions]
  return {"root_step_max": spread(each), "per_motion": {"root_step_max": each}}


@metric("kinetic FID", "fid_k", "div_k")
def kinetic_fid(j: Judged) -> dict:
  """Frechet distance on kinetic window features (and the reference halves' own), diversity of both.

  None each, with ``fid_note``, where the reference is too short for a distribution."""

  def measure():
    fid, real, div, div_real = j.distribution(j.motions, j.kinetic, 1e-10)
    return {"fid_k": spread(fid), "fid_k_real": spread(real), "div_k": div, "div_k_real": div_real}

  return _measured(("fid_k", "fid_k_real", "div_k", "div_k_real"), measure)


@metric("geometric FID", "fid_g", "div_g")
def geometric_fid(j: Judged) -> dict:
  """Frechet distance on geometric (pose question) window features (and the reference's own), diversity.

  None each, with ``fid_note``, where the reference is too short for a distribution."""

  def measure():
    fid, real, div, div_real = j.distribution(j.motions, _pose_features(j.skeleton, j.size), GEO_STD_FLOOR)
    return {"fid_g": spread(fid), "fid_g_real": spread(real), "div_g": div, "div_g_real": div_real}

  return _measured(("fid_g", "fid_g_real", "div_g", "div_g_real"), measure)


@metric("feet", "pfc", "foot_sliding", "airborne")
def feet(j: Judged) -> dict:
  """EDGE's physical foot contact score, the feet's slide in contact, the frames every foot is in the air."""
  sk, fps, size = j.skeleton, j.fps, j.size
  return {
    "pfc": spread([metrics.pfc(m, sk, fps, size) for m in j.motions]),
    "data_pfc": float(np.mean([metrics.pfc(t, sk, fps, size) for t in j.reference])),
    "foot_sliding": spread([metrics.foot_sliding(m, sk, fps, size) for m in j.motions]),
    "data_foot_sliding": float(np.mean([metrics.foot_sliding(t, sk, fps, size) for t in j.reference])),
    "airborne": spread([metrics.airborne(m, sk, size) for m in j.motions]),
    "airborne_real": float(np.mean([metrics.airborne(t, sk, size) for t in j.reference])),
  }


@metric("novelty", "novelty")
def novelty(j: Judged) -> dict:
  """RMS joint distance from each window to its nearest training window (or reference window)."""
  root, window = j.skeleton.root, j.window
  wins = lambda takes, hop: np.concatenate([metrics.windows(t, window, hop) for t in takes]) / j.size
  if j.train:
    train_w = wins(j.train, window // 4)
    real = metrics.novelty(wins(j.unseen, window // 4), train_w, root) if j.unseen else None
    return {"novelty": metrics.novelty(wins(j.motions, window), train_w, root), "novelty_real": real}
  others = lambda i: [t for k, t in enumerate(j.reference) if k != i]
  real = (
    [metrics.novelty(wins([t], window // 4), wins(others(i), window // 4), root) for i, t in enumerate(j.reference)]
    if len(j.reference) > 1
    else [float("nan")]
  )
  return {
    "novelty": metrics.novelty(wins(j.motions, window), wins(j.reference, window // 4), root),
    "novelty_real": spread(real),
  }


@metric("speed", "speed")
def speed(j: Judged) -> dict:
  """Mean joint speed per frame / the reference's (trembling is fast too: read it with jitter)."""
  reference = metrics.pooled_speed(j.reference)
  speeds = spread([metrics.speed_ratio(m, reference) for m in j.motions])
  return {"speed_ratio": speeds, "speed": speeds}  # speed_ratio: the name before `speed`, kept for older readers


@metric("root travel", "root_travel")
def root_travel(j: Judged) -> dict:
  """The root's path length per frame / the reference's (a dancer who stays on one spot: 0)."""
  travel = lambda p: metrics.root_travel(p, j.skeleton.root)
  ref_travel = metrics.pooled_root_travel(j.reference, j.skeleton.root)
  return {"root_travel": spread([float(travel(m).mean() / max(ref_travel, 1e-12)) for m in j.motions])}


@metric("training takes")
def training_takes(j: Judged) -> dict:
  """The training takes scored as a sample against held-out takes: fid_k_train and fid_g_train."""
  out: dict = {}
  geo = _pose_features(j.skeleton, j.size)
  for name, feats, floor in (("fid_k_train", j.kinetic, 1e-10), ("fid_g_train", geo, GEO_STD_FLOOR)):
    measure = lambda name=name, feats=feats, floor=floor: {name: spread(j.distribution(j.train, feats, floor)[0])}
    out |= _measured((name,), measure) if j.train and j.unseen else {name: None}
  return out


SINGLE_TAKE_FRAMES = 3600  # the single-take measures for takes of up to two minutes at 30 fps (one take: 10-60 s)


@metric("one take", "coverage", "global_diversity", "local_diversity", "inter_diversity")
def one_take(j: Judged) -> dict:
  """Coverage and diversities against the one take the motions were drawn from (chorjax.evaluation.single_take).

  Against the training takes (``chorjax metrics``: the reference), where those hold at most
  ``SINGLE_TAKE_FRAMES`` frames; else None each."""
  takes = j.train if j.train is not None else j.reference
  if sum(len(t) for t in takes) > SINGLE_TAKE_FRAMES:
    return dict.fromkeys(KEYS)
  return single_take(j.motions, takes, j.skeleton, j.size)


def _check_reference(reference, skeleton: Skeleton, fps: float, size: float) -> None:
  """One line (naming ``--data``) where the reference takes cannot be measured against: no body (every joint
  in one point), no motion (a frozen take: movement and jitter are ratios to theirs), or a single frame."""
  if not all(len(t) >= 2 for t in reference):
    raise UserError("--data: a reference take holds a single frame: nothing to measure motion against")
  if not size > 1e-9:
    raise UserError("--data: the reference takes have no body (every joint at one point): nothing to measure")
  lag = max(round(0.5 * fps), 1)
  if max(len(t) for t in reference) <= lag:
    raise UserError(f"--data: the reference takes are shorter than half a second ({lag} frames): too short to measure")
  disp, rough = metrics.reference_rates(reference, skeleton.root, lag)
  if not (disp > 1e-9 * size and rough > 1e-12 * size):
    raise UserError("--data: the reference takes do not move (frozen): nothing to measure motion against")


def score(
  motions,
  reference,
  skeleton: Skeleton,
  fps: float,
  *,
  train=None,
  unseen=None,
  window: int = 60,
  splits: int = 10,
  segment: int = 1000,
  seed: int = 0,
) -> dict:
  """The metrics of ``motions`` (list of ``[T, J, 3]``, y-up) against ``reference`` takes (same form).

  Args:
    motions: the motions to score (samples, or real takes).
    reference: real takes of the same skeleton: the divisors and the distributions compared with.
    skeleton: their skeleton (mpii16 for the geometric features).
    fps: frame rate of all of them.
    train: the training takes, if any (novelty is measured against them).
    unseen: real takes that are not training takes (``novelty_real`` is theirs; None without any).
    window: frames per window of the FID and diversity features (60 = 2 s at 30 fps).
    splits: how many random halvings of the reference the FIDs are averaged over.
    segment: frames per segment of the movement and jitter measures.
    seed: the seed of those halvings and subsamples.

  Returns:
    The JSON-ready dict described in the module docstring (plus a few labelled extras).
  """
  size = float(np.mean([metrics.body_size(t, skeleton) for t in reference]))
  _check_reference(reference, skeleton, fps, size)
  judged = Judged(motions, reference, skeleton, fps, train, unseen, window, splits, segment, seed, size)
  out: dict = {}
  per_motion: dict = {}
  for m in METRICS.values():
    measured = m.measure(judged)
    per_motion.update(measured.pop("per_motion", {}))
    out.update(measured)
  return {**out, "per_motion": per_motion, "body_size": size, "window": window, "splits": splits}


def score_files(motion_specs, data_specs, **kw) -> dict:
  """``chorjax metrics``: :func:`score_motions` of motion files against real takes, any formats."""
  data_cfg = DataConfig()
  reference = read_takes(list(data_specs), data_cfg)
  result = score_motions(read_takes(list(motion_specs), data_cfg), reference, **kw)
  return {"motions": result.pop("motions"), "data": list(data_specs), **result}


def score_motions(motions, reference, **kw) -> dict:
  """:func:`score` of motions (Motions of any skeleton the 16-joint layout maps) against real takes.

  Every motion is brought to the reference's frame rate (resampled) and body size (scaled), so
  another system's output is measured with the same ruler as a chorjax sample.
  """
  check_options(kw)
  if not reference or not motions:
    raise UserError(f"{'--data' if not reference else 'MOTION'}: no takes found")
  reference, motions = [to_mpii16(m) for m in reference], [to_mpii16(m) for m in motions]
  fps, skeleton = reference[0].fps, reference[0].skeleton
  y_up = lambda m: np.asarray(transforms.to_y_up(m.positions, m.up_axis), np.float64)
  ref = [y_up(m) for m in reference]
  size = float(np.mean([metrics.body_size(r, skeleton) for r in ref]))
  out = []
  for m in motions:
    p = y_up(m)
    if m.fps != fps:
      p = np.asarray(transforms.resample(p, m.fps, fps, m.source or m.name), np.float64)
    out.append(p * (size / metrics.body_size(p, skeleton)))
  short = [m.name for m, p in zip(motions, out) if len(p) < 2 * kw.get("window", 60)]
  if short:
    raise UserError(f"{short[0]}: too short to score (need at least {2 * kw.get('window', 60)} frames)")
  result = score(out, ref, skeleton, fps, **kw)
  return {"motions": [m.name for m in motions], "fps": fps, **result}


# The scoring options and the whole numbers each may be: beyond the highest, minutes of work that say nothing more.
OPTIONS = {"window": (4, 10_000), "splits": (1, 1_000), "segment": (1, 2**31 - 1), "seed": (0, 2**32 - 1)}


def check_options(kw: dict) -> None:
  """Refuses, in one line naming it, an option :func:`score` does not take (with the closest name) or a value
  outside ``OPTIONS`` (a bool, a float and text included): the CLI's flags and the API's keywords alike."""
  for name, value in kw.items():
    if name not in OPTIONS:
      raise UserError(
        f"{name!r} is not a scoring option{suggest(name, list(OPTIONS)) or '; they are ' + ', '.join(OPTIONS)}"
      )
    low, high = OPTIONS[name]
    if not isinstance(value, int) or isinstance(value, bool) or not low <= value <= high:
      raise UserError(f"{name} {value!r}: must be a whole number from {low:,} to {high:,}")


def score_to(motion_specs, data_specs, output=None, *, force: bool = False, **kw) -> tuple[dict, Path | None]:
  """``chorjax metrics``: :func:`score_files` (``kw``: ``window``, ``splits``, ``seed``), written as JSON to
  ``output`` where given (not replaced unless ``force``). Returns ``(the result, the JSON written or None)``."""
  check_options(kw)
  out = check_output(output, (".json",))[0] if output else None
  if out is not None:
    refuse_existing([out], force)
  result = score_files(motion_specs, data_specs, **kw)
  if out is not None:
    atomic_write(out, lambda p: p.write_text(json.dumps(result, indent=2)))
  return result, out
