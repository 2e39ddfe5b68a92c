"""What the commands that look at takes and runs report: the takes table (``data info``), a data check's
table, notes and fatal problems (``data check``), and the metrics lines (``metrics``, ``eval``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rich.table import Table

from chorjax.data.check import check_paths
from chorjax.data.dataset import read_takes
from chorjax.data.motion import bone_length_cv
from chorjax.evaluation.scoring import METRICS, mean_of
from chorjax.evaluation.single_take import KEYS as SINGLE_TAKE_KEYS

# printed only where measured: the single-take measures (takes of up to two minutes; two samples for inter_)
WHERE_MEASURED = tuple(k for k in SINGLE_TAKE_KEYS if k != "coverage_together")


def metric_keys() -> tuple[str, ...]:
  """The keys `chorjax metrics` and `chorjax eval` print, metric by metric (every one is in the JSON): what each
  metric registered in chorjax/evaluation/scoring.py says it prints, asked when printing (a metric registered
  counts)."""
  return tuple(k for m in METRICS.values() for k in m.printed)


INFO_COLUMNS = ("take", "frames", "joints", "fps", "x range", "y range", "z range")
BONE_COLUMNS = ("bone len (mean)", "bone CV median", "bone CV max")
CHECK_COLUMNS = ("take", "frames", "fps", "seconds", "joints", "up", "units", "bone CV", "held", "jumps")


def _table(columns, left):
  table = Table(title="takes", show_lines=False)
  for col in columns:
    table.add_column(col, justify="left" if col in left else "right")
  return table


def takes_table(inputs):
  """A table of the takes in ``inputs`` (files, folders or bundled names): frames, joints, rate, extent and
  how steady their bones are (a rich ``Table``)."""
  table = _table((*INFO_COLUMNS, *BONE_COLUMNS), ("take",))
  for m in read_takes(inputs):
    lo, hi = m.positions.min(axis=(0, 1)), m.positions.max(axis=(0, 1))
    bones = ["-"] * 3  # marker sets (C3D) have no bones
    if m.skeleton.bones:
      cv = bone_length_cv(m.positions, m.skeleton) * 100
      bones = [f"{m.bone_lengths().mean():.4g}", f"{np.median(cv):.2f}%", f"{cv.max():.2f}%"]
    extent = [f"{lo[i]:.4g}..{hi[i]:.4g}" for i in range(3)]
    table.add_row(m.name, str(m.num_frames), str(m.skeleton.num_joints), f"{m.fps:g}", *extent, *bones)
  return table


def check_report(inputs, joint_map=None, fps: float = 30.0) -> tuple:
  """``data check`` of ``inputs``: ``(a table of the readable takes, the lines that explain them and give
  the config keys for the set, the fatal problems)``."""
  reports, config = check_paths(inputs, joint_map=joint_map, fps=fps)
  table = _table(CHECK_COLUMNS, ("take", "up", "units", "bone CV"))
  good = [r for r in reports if not r.fatal]
  lines = []
  for r in good:
    row = (r.frames, f"{r.fps:g}", f"{r.duration:.1f}", r.joints, r.up_axis, r.units, r.bone_cv or "-")
    table.add_row(Path(r.path).name, *map(str, row), str(r.held_frames), str(r.teleports))
    lines += [
      f"{r.path}:",
      f"  up axis {r.up_axis}: {r.up_evidence}",
      f"  units {r.units}: {r.units_evidence}",
      f"  skeleton {r.skeleton} ({r.joints} joints), mapped by {r.mapping or '-'}",
      f"  floor under the feet, first -> last second: {r.floor}",
      *(f"  note: {note}" for note in r.notes),
    ]
  total, seconds = sum(r.frames for r in good), sum(r.duration for r in good)
  lines.append(f"{len(good)} of {len(reports)} takes readable: {total} frames, {seconds / 60:.1f} minutes")
  if config:
    lines += ["config keys for these takes:", *(f"  {line}" for line in config)]
  return table, lines, [line for r in reports for line in r.fatal]


def metric_lines(result: dict, keys) -> list[str]:
  """The metrics of ``result`` (``scoring.score``, ``evaluate.evaluate``) as ``chorjax metrics`` prints them:
  a key a line, its value, and the real takes' (and the training takes') beside it."""
  lines = []
  if "segment_frames" in result:
    lines.append(f"segments of {result['segment_frames']} frames (movement_first/last/min/max, jitter_max)")
  if result.get("fid_note"):
    lines.append(f"note: {result['fid_note']}")
  for k in keys:
    real = result.get(k + "_real")
    if result.get(k) is None and k in WHERE_MEASURED:
      continue
    if result.get(k) is None:
      lines.append(f"{k:22s} {'-':>10s}   (none: a GAN has no likelihood)" if k == "heldout_loss" else f"{k:22s} -")
      continue
    note = f"   (real: {mean_of(real):.4g})" if real is not None else ""
    if result.get(k + "_train") is not None:  # the training takes against the held-out ones
      note += f"   (training takes: {mean_of(result[k + '_train']):.4g})"
    if k == "heldout_loss" and result.get("loss_takes") == "all":
      note = "   (on the run's own training takes: --data holds no other)"
    lines.append(f"{k:22s} {mean_of(result[k]):10.4g}{note}")
  return lines
