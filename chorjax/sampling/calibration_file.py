"""A run's calibration file (``calibration.json``, written by ``chorjax calibrate``): the sampling settings
it chose and the table it measured, read back and checked."""

from __future__ import annotations

import json
from pathlib import Path

from chorjax.errors import UserError, load_json
from chorjax.sampling.table import CALIBRATED


def calibration_path(workdir) -> Path:
  return Path(workdir) / "calibration.json"


def _damaged_calibration(workdir) -> UserError:
  return UserError(
    f"{calibration_path(workdir)}: damaged calibration; run `chorjax calibrate {workdir}` again (or delete it)"
  )


def _calibration(workdir) -> dict | None:
  """``calibration.json`` as a dict (None when the run was never calibrated); one line if it is not JSON."""
  path = calibration_path(workdir)
  if not path.is_file():
    return None
  try:
    return load_json(path.read_text(errors="replace"))
  except json.JSONDecodeError:
    raise _damaged_calibration(workdir) from None


def read_calibration(workdir) -> dict:
  """The calibrated controls of a run (``{}`` when it was never calibrated)."""
  cal = _calibration(workdir)
  if cal is None:
    return {}
  try:
    settings = cal["settings"]
  except (KeyError, TypeError):
    raise _damaged_calibration(workdir) from None
  if not isinstance(settings, dict) or set(settings) - set(CALIBRATED):
    raise _damaged_calibration(workdir)
  return settings


def chosen_calibration_row(workdir) -> dict | None:
  """The row of ``calibration.json``'s table measured with the settings it chose (its objective and rates
  against the run's training takes); None if the run was never calibrated or its settings were edited by
  hand (no measured row is theirs)."""
  cal = _calibration(workdir)
  if cal is None:
    return None
  try:
    return next((r for r in cal["table"] if r["settings"] == cal["settings"]), None)
  except (KeyError, TypeError, AttributeError):
    raise _damaged_calibration(workdir) from None
