"""``chorjax calibrate``: the sampling settings a run's dance depends on, chosen on its dancer's takes.

Calibration draws the trained model over a grid of the controls that set how much and how smoothly it moves
(``table.GRID``; ``table.CARRIED_GRID`` for an MDN that carries its noise): the noise smoothing, the scale
temperature, persistence and crossfade and, for canonical runs, foot lock. Where one of the three best
settings' value of a walked control is an end of the grid, it goes on past that end (``BEYOND``) while the
objective falls. The objective, smallest wins, compares each setting's dancers with the reference takes, each
measure over the reference's: ``|log movement| + |log jitter| + |log speed| + |log root travel|`` (movement over
half a second, which trembling cannot fake; the second difference, which over-smoothing pulls under 1; mean
joint speed; how far the root goes; each pooled over the frames as ``chorjax eval`` pools them), plus the
largest of those four again (every measure near, not only their sum), plus ``max(log poses, 0)``: the
geometric FID of the dancers against the reference over the reference's own (one half of its takes against
the other). The noise order and the pace governor's gain are not searched: the settings are chosen under the
run's (or ``--noise-order`` / ``--pace``) and recorded with them.

The reference is the run's TRAINING takes (never the takes it is judged on: tuning on those would be
tuning on the test); ``--data`` names others. The result goes to ``WORKDIR/calibration.json`` and is the
run's default from then on (``sample``, ``eval``, ``live``; a flag or key given explicitly still wins).
Each setting draws four dancers, each conditioned on one of the reference takes; a run conditioned on labels
draws sixteen, on takes spread over the reference (a library's names sort by label: its first four takes are
one action), and holds each dancer's poses to the training takes of its own labels (``PosesByLabel``), not to
the whole library's. Why each part is there, measured: ``docs/perf-notes.md`` ("Calibration").
"""

from __future__ import annotations

import contextlib
import itertools
import json
import math
import sys
from collections.abc import Sequence

import jax
import numpy as np
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from chorjax.data.transforms import to_y_up
from chorjax.errors import UserError, atomic_write, refuse_existing
from chorjax.evaluation import metrics, scoring
from chorjax.run import load_run, read_reference
from chorjax.runtime import side_by_side
from chorjax.sampling.calibration_file import calibration_path, read_calibration  # noqa: F401  (re-exported)
from chorjax.sampling.table import (  # noqa: F401
  BEYOND,
  CALIBRATED,
  CARRIED_BEYOND,
  CARRIED_GRID,
  DECODING,
  GRID,
  RECORDED,
  check_sample_control,
)

# The walk starts from each of the grid's WALKS best settings: from the best alone it missed, on one martial run,
# a setting a quarter nearer (objective 0.51 against 0.67) that the third best's walk reaches.
WALKS = 3
RATES = ("movement", "jitter", "speed", "root_travel")
MEASURES = (*RATES, "poses")


CALIBRATION_DANCERS = 4  # dancers drawn per setting
CALIBRATION_FRAMES = 1200  # frames per dancer
# ... for an MDN that carries its noise, whose small grid affords longer draws: at 1,200 frames the pose measure
# is noisy enough to pick a scale temperature whose calmest 1,000 of 10,000 frames fall under the bar
# (docs/perf-notes.md, "Calibration")
CARRIED_FRAMES = 3600
# A labelled library's dancers: its label combinations are many, and a few dancers would stand for one action
# (on Bandai's library, 16 spread over its takes against the first 4, four bows, three training seeds: samples
# named their action at 0.39-0.48 of the held-out takes' rate against 0.27-0.45, their style at 0.35-0.40
# against 0.38-0.40; experiments/library)
LABELLED_DANCERS = 16


def default_grid(config, noise_order: int | None = None, pace: float | None = None) -> dict:
  """``GRID`` (``CARRIED_GRID`` for an MDN that carries its noise: ``model.mdn_memory``) less what ``config``'s
  run cannot use: ``foot_lock`` needs canonical features, and an MSE head
  draws no noise (its frame is its prediction), so only ``foot_lock`` can change its dance. The noise passes
  ``noise_order`` filters and the governor holds the pace with gain ``pace`` (defaults: the run's
  ``sample.noise_order`` and ``sample.pace``), both recorded with the settings chosen."""
  pace = config.sample.pace if pace is None else pace
  searched = CARRIED_GRID if config.model.memory else GRID
  grid = {"noise_order": (noise_order or config.sample.noise_order,), "pace": (pace,), **searched}
  if config.data.representation != "canonical":
    del grid["foot_lock"]
  if config.model.head == "mse":
    grid = {k: v for k, v in grid.items() if k in DECODING}
  return grid


def default_frames(config) -> int:
  """Frames per dancer: ``CARRIED_FRAMES`` for an MDN that carries its noise, else ``CALIBRATION_FRAMES``."""
  return CARRIED_FRAMES if config.model.memory else CALIBRATION_FRAMES


def objective(measured: dict) -> float:
  """How far a sample's ``MEASURES`` (each / the reference's) are from the reference's own: the rates' summed
  and largest ``|log|``; ``poses`` counts only above 1 (and not in tables recorded before it was measured)."""
  off = [abs(np.log(max(measured[k], 1e-9))) for k in RATES]
  return float(sum(off) + max(off) + max(np.log(max(measured.get("poses", 1.0), 1e-9)), 0.0))


class PosesByLabel:
  """``poses`` for a run conditioned on labels: each dancer's poses against the training takes of its own
  labels (their geometric FID over their own, as ``scoring.PoseDistribution``), the geometric mean over the
  dancers' label combinations. Against the whole library pooled, a dancer that wanders through every action's
  poses is the nearest (a labelled run's calibration chose no component persistence for it, and its samples
  were named their action at 0.47 of the held-out takes' rate against 0.67 with persistence 6;
  experiments/library). A combination with fewer than ``MIN_TAKES`` takes of two windows or more is left out;
  with none left, the pooled distribution stands in."""

  MIN_TAKES = 4

  def __init__(self, reference, skeleton, take_conditions, dancer_conditions, window: int = 60):
    key = lambda c: np.asarray(c).tobytes()
    long = max(window // 4, 1) + window  # two windows at the reference's hop
    self.groups = []  # (PoseDistribution of one combination's takes, the indices of its dancers)
    for k in dict.fromkeys(map(key, dancer_conditions)):
      takes = [t for t, c in zip(reference, take_conditions) if key(c) == k and len(t) >= long]
      if len(takes) >= self.MIN_TAKES:
        dancers = [i for i, c in enumerate(dancer_conditions) if key(c) == k]
        self.groups.append((scoring.PoseDistribution(takes, skeleton, window), dancers))
    self.pooled = None if self.groups else scoring.PoseDistribution(reference, skeleton, window)

  def ratio(self, motions) -> float:
    """The dancers' (``[T, J, 3]`` each, in the order of ``dancer_conditions``) geometric mean FID_g ratio."""
    if self.pooled is not None:
      return self.pooled.ratio(motions)
    ratios = [d.ratio([motions[i] for i in dancers]) for d, dancers in self.groups]
    return float(np.exp(np.mean(np.log(np.maximum(ratios, 1e-9)))))


def reference_rates(reference, skeleton, fps: float, poses=None) -> dict:
  """The reference takes' own rates and pose windows, what ``measure`` compares with (once per search);
  ``poses``: what measures the poses instead of the pooled reference's distribution (``PosesByLabel``)."""
  root = skeleton.root
  lag = max(round(0.5 * fps), 1)
  disp, rough = metrics.reference_rates(reference, root, lag)
  return {
    "lag": lag,
    "movement": disp,
    "jitter": rough,
    "speed": max(metrics.pooled_speed(reference), 1e-12),
    "root_travel": max(metrics.pooled_root_travel(reference, root), 1e-12),
    "poses": poses or scoring.PoseDistribution(reference, skeleton),
  }


def measure(samples, rates: dict, root: int) -> dict:
  """``MEASURES`` of samples ``[B, T, J, 3]`` (y-up) / the reference's ``rates`` (``reference_rates``)."""
  return {
    "movement": float(np.mean([metrics.displacement(s, root, rates["lag"]) for s in samples]) / rates["movement"]),
    "jitter": float(np.mean([metrics.roughness(s) for s in samples]) / rates["jitter"]),
    "speed": metrics.pooled_speed(samples) / rates["speed"],
    "root_travel": metrics.pooled_root_travel(samples, root) / rates["root_travel"],
    "poses": rates["poses"].ratio(list(samples)),
  }


def search(
  draw,
  reference,
  skeleton,
  fps: float,
  grid: dict | None = None,
  tick=None,
  beyond: dict | None = None,
  known: Sequence | None = None,
  poses=None,
) -> tuple[dict, list]:
  """``(best settings, table)``: every combination of ``grid`` drawn by ``draw(settings) -> [B, T, J, 3]``
  (y-up) and measured against ``reference`` (takes of ``skeleton``), then, from each of the grid's ``WALKS``
  best settings whose value of a control in ``beyond`` (default ``BEYOND``) is an end of the grid's values,
  the ladder's next values past that end with the other controls held (while the objective falls); the table
  rows are ``(settings, measures, objective)``, the grid's first, each setting once. The grid's settings are
  drawn side by side (``runtime.side_by_side``: ``draw`` must allow two threads).
  ``known``: ``(settings, measures)`` pairs measured before with the same draws (a calibration table of the same
  checkpoint, frames, dancers and seed), not drawn again. ``poses``: see :func:`reference_rates`. ``tick``:
  called with the number of settings in the table each time one is added (a progress bar)."""
  grid = grid or GRID
  beyond = BEYOND if beyond is None else beyond
  rates = reference_rates(reference, skeleton, fps, poses)
  before = {json.dumps(s, sort_keys=True): m for s, m in known or ()}
  drawn = {}  # the table, in the order drawn: each setting once, however many walks reach it

  def measured(settings) -> dict:
    return before.get(json.dumps(settings, sort_keys=True)) or measure(draw(settings), rates, skeleton.root)

  def row(settings, found=None):
    key = json.dumps(settings, sort_keys=True)
    if key not in drawn:
      found = found or measured(settings)
      drawn[key] = (settings, found, objective(found))
      if tick:
        tick(len(drawn))
    return drawn[key]

  settings = [dict(zip(grid, values)) for values in itertools.product(*grid.values())]
  for one, found in zip(settings, side_by_side(measured, settings)):  # into the table in grid order
    row(one, found)
  for start in sorted(drawn.values(), key=lambda r: r[2])[:WALKS]:
    _walk(row, start, grid, beyond)
  table = list(drawn.values())
  return min(table, key=lambda r: r[2])[0], table


def _walk(row, best, grid: dict, beyond: dict) -> None:
  """From ``best`` (a table row), each control of ``beyond`` whose value is an end of the grid's goes on past
  that end, one ladder value at a time, while the objective falls (``row(settings)`` draws and records)."""
  for name, (lower, higher) in beyond.items():
    values = grid.get(name, ())
    if len(values) < 2 or best[0][name] not in (min(values), max(values)):
      continue
    down = best[0][name] == min(values)
    for value in [v for v in lower if v < min(values)] if down else [v for v in higher if v > max(values)]:
      tried = row({**best[0], name: value})
      if tried[2] >= best[2]:
        break
      best = tried


def calibrate(
  workdir,
  data: Sequence[str] | None = None,
  *,
  frames: int | None = None,
  num: int | None = None,
  seed: int = 0,
  grid: dict | None = None,
  log=print,
  known: Sequence | None = None,
  noise_order: int | None = None,
  pace: float | None = None,
) -> dict:
  """Chooses and records the run's sampling settings (see the module docstring).

  Args:
    workdir: a trained run of a family whose draw calibration can change.
    data: the reference takes (default: the run's training takes).
    frames, num, seed: each setting draws ``num`` dancers of ``frames`` frames with sampling seed ``seed``
      (``frames`` default: ``CALIBRATION_FRAMES``, ``CARRIED_FRAMES`` for an MDN that carries its noise; ``num``
      default: ``CALIBRATION_DANCERS``, or ``LABELLED_DANCERS`` for a run conditioned on labels, whose
      dancers are conditioned on takes spread over the reference: ``Run.dancer_conditions``).
    grid: the values tried per control (default ``GRID``; ``foot_lock`` only where the run can lock feet).
    log: where the summary line goes (a terminal also shows a progress bar).
    known: ``(settings, measures)`` already measured with these draws (see :func:`search`).
    noise_order, pace: the drawn noise's AR(1) filters, the governor's gain (default: the run's ``sample.*``).

  Returns:
    What ``calibration.json`` holds: the settings, the reference, and every setting's measurements.
  """
  run = load_run(workdir).serving("calibrate")
  if num is None:
    num = LABELLED_DANCERS if run.labels is not None else CALIBRATION_DANCERS
  frames = default_frames(run.config) if frames is None else frames
  _check_size(frames, num)
  run.check_drawn(frames * num, f"--frames {frames} x --num {num}")
  reference, train = read_reference(run, list(data) if data else None)
  f = run.features
  motion = run.dancer_conditions(train, num)
  key = jax.random.key(seed)
  if grid is None:
    grid = default_grid(run.config, noise_order, pace)
    if not grid:
      raise UserError(f"{workdir}: an MSE head on {run.config.data.representation} features draws nothing to calibrate")
  fixed = {k: v[0] for k, v in grid.items() if k in RECORDED and len(v) == 1}
  # drawn with the run's [sample], never the calibration this replaces; the range, pace and ceiling left alone
  ranged = run.ranged(run.sampling(False, **fixed))

  y_up = lambda pos: np.asarray(to_y_up(pos, f.up_axis))  # what the measures (the pose questions) expect

  def draw(settings):
    sampling = run.sampling(False, **settings)
    return y_up(run.family.dance(ranged.graphdef, ranged.params, ranged.features, motion, key, frames, sampling))

  positions = [y_up(m.positions) for m in reference]
  poses = None
  if run.labels is not None and not data:  # each dancer against its own labels' training takes
    poses = PosesByLabel(positions, f.skeleton, [run.take_condition(m.name) for m in reference], motion)
  with _progress(math.prod(len(v) for v in grid.values())) as tick:
    beyond = CARRIED_BEYOND if run.config.model.memory else BEYOND
    best, table = search(draw, positions, f.skeleton, run.fps, grid, tick, beyond, known=known, poses=poses)
  result = {"settings": best, "reference": list(data) if data else "training takes", "frames": frames, "num": num}
  result |= {"seed": seed, "table": [{"settings": s, **m, "objective": o} for s, m, o in table]}
  atomic_write(calibration_path(workdir), lambda p: p.write_text(json.dumps(result, indent=2)))
  row = min(table, key=lambda r: r[2])
  said = ", ".join(f"{k.replace('_', ' ')} {v:.3f}" for k, v in row[1].items())
  on = f"{'the takes given' if data else 'its training takes'} ({len(reference)})"
  log(f"calibrated on {on}: {best} ({said}); wrote {calibration_path(workdir)}")
  return result


def _check_size(frames: int, num: int) -> None:
  """Refuses a search whose dancers give the pose measure fewer than two 60-frame windows (1 s apart)."""
  windows = num * ((frames - 60) // 30 + 1) if frames >= 60 else 0
  if num < 1 or windows < 2:
    raise UserError(
      f"--frames {frames} / --num {num}: the pose measure needs two 60-frame windows in all "
      "(at least --frames 90, or --frames 60 --num 2)"
    )


@contextlib.contextmanager
def _progress(grid_size: int):
  """A transient progress bar of the settings drawn on a terminal (the grid's, then the walks past its ends),
  nothing elsewhere: ``tick(settings drawn so far)``."""
  if not sys.stdout.isatty():
    yield None
    return

  with Progress(TextColumn("calibrate"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(), transient=True) as bar:
    task = bar.add_task("calibrate", total=grid_size)
    yield lambda n: bar.update(task, completed=n, total=max(grid_size, n))


def calibrate_run(workdir, data=None, *, force: bool = False, noise_order=None, pace=None, **kw) -> dict:
  """``chorjax calibrate``: :func:`calibrate` (``kw``: ``frames``, ``num``, ``seed``), refused before any draw
  where the run already has a calibration.json (unless ``force``) or ``noise_order`` / ``pace`` are not what
  ``[sample]`` allows."""
  refuse_existing([calibration_path(workdir)], force)
  if noise_order is not None:
    check_sample_control("noise_order", noise_order, "--noise-order")
  if pace is not None:
    check_sample_control("pace", pace, "--pace")
  return calibrate(workdir, data, noise_order=noise_order, pace=pace, **kw)
