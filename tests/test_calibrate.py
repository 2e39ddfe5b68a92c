"""``chorjax calibrate``: sampling settings chosen on the dancer's takes, recorded in the run, used after."""

import json

import jax
import numpy as np
import pytest
from helpers import tiny_config

from chorjax import cli
from chorjax.calibrate import calibration_path, search
from chorjax.data.npz import read_npz
from chorjax.run import load_run
from chorjax.sample import dance
from chorjax.train import train_and_evaluate

QUICKSTART_SAMPLING = [
  "data.representation=canonical",
  "sample.noise_smoothing=0.9",
  "sample.persistence=6.0",
  "sample.crossfade=0.8",
  "sample.clamp=true",
  "sample.pace=0.5",
  "sample.rigid_bones=true",
  "sample.foot_lock=true",
]
GRID = {"noise_smoothing": (0.6, 0.75, 0.85, 0.95), "sigma_temperature": (0.8, 0.9, 1.0, 1.15, 1.3, 1.5)}


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
  w = tmp_path_factory.mktemp("calibrate_run")
  train_and_evaluate(tiny_config("train.num_steps=30", "log.tensorboard=false", *QUICKSTART_SAMPLING), w)
  return w


@pytest.mark.parametrize(
  "true", [{"noise_smoothing": 0.85, "sigma_temperature": 1.3}, {"noise_smoothing": 0.6, "sigma_temperature": 0.9}]
)
def test_calibration_recovers_the_settings_that_drew_the_reference(run_dir, true):
  """A constructed case: the reference is the model's own dance drawn with known settings (sampling seed 1);
  the search, drawing with seed 0, finds exactly those settings among 24."""
  run = load_run(run_dir)

  def drawer(seed):
    def draw(settings):
      s = run.sampling(**settings)
      r = run.ranged(s)
      return dance(r.graphdef, r.params, r.features, np.arange(4) % 2, jax.random.key(seed), 400, s)

    return draw

  reference = list(drawer(1)(true))
  best, table = search(drawer(0), reference, run.features.skeleton.root, run.fps, GRID)
  assert best == true
  assert len(table) == 24 and min(o for *_, o in table) < 0.1  # movement and jitter within ~5% of the reference's


def test_calibrate_records_the_settings_and_the_run_uses_them_unless_told(run_dir, tmp_path, capsys):
  args = ["calibrate", str(run_dir), "--frames", "200", "--num", "2"]
  assert cli.main(args) == 0
  saved = json.loads(calibration_path(run_dir).read_text())
  chosen = saved["settings"]
  assert set(chosen) == {"noise_smoothing", "sigma_temperature"} and saved["reference"] == "training takes"
  assert len(saved["table"]) == 30 and "calibrated:" in capsys.readouterr().out
  assert cli.main(args) == 2  # an existing calibration is not replaced without --force
  assert "calibration.json" in capsys.readouterr().err
  out = tmp_path / "s.npz"
  assert cli.main(["sample", str(run_dir), "-o", str(out), "--frames", "30"]) == 0
  assert read_npz(out)[0].num_frames == 30
  with np.load(out) as z:  # what the sample was drawn with
    drawn = json.loads(str(z["meta"]))["settings"]
  assert {k: drawn[k] for k in chosen} == chosen  # the run's default now
  assert load_run(run_dir).sampling(sigma_temperature=0.5)["sigma_temperature"] == 0.5  # a flag still wins
  calibration_path(run_dir).write_text("{not json")
  assert cli.main(["sample", str(run_dir), "-o", str(tmp_path / "t.npz"), "--frames", "30"]) == 2
  assert "damaged calibration" in capsys.readouterr().err
  calibration_path(run_dir).unlink()
