"""``chorjax calibrate``: the sampling settings a run's dance depends on, chosen on its dancer's takes.

The quickstart's draw is shaped by controls that were set by hand on cmu94 (noise smoothing 0.9, the scale
temperature 1.0). Another dancer needs others: salsa drawn with cmu94's settings moves at 0.6 of its speed.
Calibration samples the trained model over a small grid of the two controls that set how much and how
smoothly it moves, ``noise_smoothing`` (how correlated the drawn noise is over frames: high = smooth and
slow, low = trembling) and ``sigma_temperature`` (how wide each draw is: how far the dancer goes), and
keeps the pair whose samples move like the reference takes: movement over half a second (which trembling
cannot fake) and jitter (the second difference, which over-smoothing pulls under 1) both near the
reference's, ``|log movement| + |log jitter|`` smallest.

The reference is the run's TRAINING takes (never the takes it is judged on: tuning on those would be
tuning on the test); ``--data`` names others. The result goes to ``WORKDIR/calibration.json`` and is the
run's default from then on (``sample``, ``eval``, ``live``; a flag or key given explicitly still wins).
"""

from __future__ import annotations

import itertools
import json
from collections.abc import Sequence

import jax
import numpy as np

from chorjax import metrics
from chorjax.errors import UserError, atomic_write
from chorjax.run import CALIBRATED, calibration_path, read_calibration  # noqa: F401  (re-exported)

GRID = {
  "noise_smoothing": (0.6, 0.75, 0.85, 0.9, 0.95),
  "sigma_temperature": (0.8, 0.9, 1.0, 1.15, 1.3, 1.5),
}


def objective(movement: float, jitter: float) -> float:
  """How far a sample's movement and jitter (each / the reference's) are from the reference's own."""
  return abs(np.log(max(movement, 1e-9))) + abs(np.log(max(jitter, 1e-9)))


def measure(samples, reference, root: int, fps: float) -> tuple[float, float]:
  """``(movement, jitter)`` of samples ``[B, T, J, 3]`` / the reference takes' (y-up or not: both alike)."""
  lag = max(round(0.5 * fps), 1)
  disp, rough = metrics.reference_rates(reference, root, lag)
  movement = float(np.mean([metrics.displacement(s, root, lag) for s in samples]) / disp)
  jitter = float(np.mean([metrics.roughness(s) for s in samples]) / rough)
  return movement, jitter


def search(draw, reference, root: int, fps: float, grid: dict | None = None, log=None) -> tuple[dict, list]:
  """``(best settings, table)``: every combination of ``grid`` drawn by ``draw(settings) -> [B, T, J, 3]``
  and measured against ``reference``; the table rows are ``(settings, movement, jitter, objective)``."""
  grid = grid or GRID
  table = []
  for values in itertools.product(*grid.values()):
    settings = dict(zip(grid, values))
    movement, jitter = measure(draw(settings), reference, root, fps)
    table.append((settings, movement, jitter, objective(movement, jitter)))
    if log:
      log(f"  {settings}: movement {movement:.3f}, jitter {jitter:.3f}")
  best = min(table, key=lambda row: row[3])
  return best[0], table


def calibrate(
  workdir,
  data: Sequence[str] | None = None,
  *,
  frames: int = 1200,
  num: int = 4,
  seed: int = 0,
  grid: dict | None = None,
  log=print,
) -> dict:
  """Chooses and records the run's ``noise_smoothing`` and ``sigma_temperature`` (see the module docstring).

  Args:
    workdir: a trained run (rnn family).
    data: the reference takes (default: the run's training takes).
    frames, num, seed: each setting draws ``num`` dancers of ``frames`` frames with sampling seed ``seed``.
    grid: the values tried per control (default ``GRID``).
    log: where progress lines go.

  Returns:
    What ``calibration.json`` holds: the settings, the reference, and every setting's measurements.
  """
  from chorjax.run import load_run, read_reference
  from chorjax.sample import dance

  if frames < 60 or num < 1:
    raise UserError(f"--frames {frames} / --num {num}: need at least 60 frames and 1 dancer")
  run = load_run(workdir).generating("calibrate")
  if run.is_gan:
    raise UserError(f"{workdir}: a GAN draws whole sequences from noise; there is nothing to calibrate")
  reference, train = read_reference(run, list(data) if data else None)
  f = run.features
  ids = [run.id_map[m.name] for m in train] or [0]
  motion = np.array([ids[k % len(ids)] for k in range(num)])
  key = jax.random.key(seed)
  ranged = run.ranged(run.sampling())  # the grid's controls leave the range, pace and scale ceiling alone

  def draw(settings):
    sampling = run.sampling(**settings)
    return dance(ranged.graphdef, ranged.params, ranged.features, motion, key, frames, sampling)

  log(f"calibrating {workdir} on {'the takes given' if data else 'its training takes'} ({len(reference)} takes)")
  positions = [m.positions for m in reference]
  best, table = search(draw, positions, f.skeleton.root, run.fps, grid, log)
  result = {
    "settings": best,
    "reference": list(data) if data else "training takes",
    "frames": frames,
    "num": num,
    "seed": seed,
    "table": [{"settings": s, "movement": m, "jitter": j, "objective": o} for s, m, j, o in table],
  }
  atomic_write(calibration_path(workdir), lambda p: p.write_text(json.dumps(result, indent=2)))
  row = min(table, key=lambda r: r[3])
  log(f"calibrated: {best} (movement {row[1]:.3f}, jitter {row[2]:.3f}); wrote {calibration_path(workdir)}")
  return result
