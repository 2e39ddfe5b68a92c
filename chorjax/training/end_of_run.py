"""What a run does once it has trained all its steps: hooks the training driver runs in the main process,
handed to it by whoever trains (``chorjax.train``, ``chorjax train``, sweeps); :func:`standard` is what
they hand it: calibration and the sample drawn with it (``train.calibrate``), else the end sample."""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path
from typing import Any

import numpy as np

from chorjax.families import family_of
from chorjax.io.output import as_motions, write_motions
from chorjax.run import load_run, save_ceiling
from chorjax.sampling.calibrate import calibrate, default_grid
from chorjax.sampling.controls import Controls, scale_ceiling


@dataclasses.dataclass(frozen=True)
class Finished:
  """A run that has trained all its steps: its directory, dataset, config and final parameters."""

  workdir: Path
  ds: Any
  cfg: Any
  graphdef: Any
  params: Any

  @functools.cached_property
  def kept(self):
    """The run as sample, eval and export load it (its kept checkpoint), read once for every hook."""
    return load_run(self.workdir)


def standard(cfg) -> list:
  """The hooks ``chorjax train`` ends a run of ``cfg`` with: the scale ceiling its draw needs recorded with
  it (``sample.scale_cap``), then calibration and the sample drawn with it (``train.calibrate``), else the end
  sample."""
  first = [record_ceiling] if cfg.sample.scale_cap and family_of(cfg).calibrated else []
  if calibrates(cfg):
    return [*first, calibration]
  return [*first, end_sample] if cfg.sample.frames > 0 else first


def record_ceiling(run: Finished) -> dict:
  """``sample.scale_cap``'s ceiling for the kept checkpoint, measured on the training takes and saved in the
  run (``run.save_ceiling``): the run samples without its training data (moved, deleted, or a relative
  path read from elsewhere)."""
  kept = run.kept
  q = run.cfg.sample.scale_cap
  ceiling = scale_ceiling(kept.graphdef, kept.params, run.ds.train, run.cfg.data.seq_length, q)
  if np.all(np.isfinite(ceiling)):  # an MSE head has no scales to hold
    save_ceiling(run.workdir, kept.step, q, ceiling)
  return {}


def calibrates(cfg) -> bool:
  """Whether training ends by calibrating (``train.calibrate``; a family whose draw a control can change)."""
  return cfg.train.calibrate and family_of(cfg).calibrated and bool(default_grid(cfg))


def calibration(run: Finished) -> dict:
  """``train.calibrate``: ``chorjax calibrate`` on the kept checkpoint, then the end sample drawn with it."""
  calibrate(run.workdir, log=lambda line: print(line, flush=True))
  if run.cfg.sample.frames <= 0:
    return {}
  kept = run.kept  # its sampling reads the calibration just written
  return write_end_sample(run.workdir, kept.graphdef, kept.params, run.ds, run.cfg, kept.sampling())


def end_sample(run: Finished) -> dict:
  """The end sample drawn with the run's ``[sample]`` from the checkpoint the run keeps (``train.keep =
  "best"``: the best validation loss, as ``chorjax sample`` draws; else the final parameters)."""
  params = run.kept.params if run.cfg.train.keep == "best" else run.params
  return write_end_sample(run.workdir, run.graphdef, params, run.ds, run.cfg)


def write_end_sample(workdir: Path, graphdef, params, ds, cfg, controls: Controls | None = None) -> dict:
  """``samples/sample.csv`` and ``samples/player.html``: the dance the run ends with, as its family draws it
  (``Family.end_sample``: the generated dancers beside a real take, or an in-betweening piece beside its take)."""
  controls = controls or Controls.resolve(cfg.sample)
  named = dataclasses.replace(cfg, name=Path(workdir).resolve().name)  # a run is named by its folder
  positions, motions, title = family_of(cfg).end_sample(graphdef, params, ds, named, controls)
  first = as_motions(positions[None], ds.fps, ds.features.skeleton, ds.features.up_axis)
  csv = write_motions(Path(workdir) / "samples" / "sample.csv", first)[0]
  html = write_motions(Path(workdir) / "samples" / "player.html", motions, title=title)[0]
  return {"csv": str(csv), "html": str(html)}
