"""``chorjax calibrate``: sampling settings chosen on the dancer's takes, recorded in the run, used after."""

import itertools
import json
from types import SimpleNamespace

import jax
import numpy as np
import pytest
from helpers import QUICKSTART_SAMPLING, tiny_config

from chorjax import cli, runtime
from chorjax.data.npz import read_npz
from chorjax.data.transforms import to_y_up
from chorjax.errors import UserError
from chorjax.families.recurrent.generation import dance
from chorjax.run import load_run
from chorjax.sampling import calibrate
from chorjax.sampling.calibrate import calibration_path, search
from chorjax.sampling.calibration_file import CALIBRATED, chosen_calibration_row
from chorjax.sampling.controls import Draw, Pacing
from chorjax.training.driver import train_and_evaluate

GRID = {"noise_smoothing": (0.6, 0.75, 0.85, 0.95), "sigma_temperature": (0.8, 0.9, 1.0, 1.15, 1.3, 1.5)}
# What the commands below search: every control of the shipped grid, two values of two (the whole grid,
# 180 draws, would take most of a minute for what these tests check).
SMALL = {
  "noise_smoothing": (0.75, 0.9),
  "sigma_temperature": (1.0,),
  "persistence": (0.0,),
  "crossfade": (0.8,),
  "foot_lock": (True, False),
}


@pytest.fixture
def small_grid(monkeypatch):
  assert set(SMALL) == set(calibrate.GRID) == set(CALIBRATED) - set(calibrate.RECORDED)  # recorded, not searched
  monkeypatch.setattr(calibrate, "GRID", SMALL)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
  w = tmp_path_factory.mktemp("calibrate_run")
  train_and_evaluate(tiny_config("train.num_steps=30", "log.tensorboard=false", *QUICKSTART_SAMPLING), w)
  return w


def _drawer(run, seed: int):
  """``draw(settings)``: 4 dancers of 400 frames from ``run`` with sampling seed ``seed``, y-up."""

  def draw(settings):
    s = run.sampling(**settings)
    r = run.ranged(s)
    pos = dance(r.graphdef, r.params, r.features, np.arange(4) % 2, jax.random.key(seed), 400, s)
    return np.asarray(to_y_up(pos, r.features.up_axis))

  return draw


@pytest.mark.parametrize(
  "true", [{"noise_smoothing": 0.85, "sigma_temperature": 1.3}, {"noise_smoothing": 0.6, "sigma_temperature": 0.9}]
)
def test_calibration_recovers_the_settings_that_drew_the_reference(run_dir, true):
  """A constructed case: the reference is the model's own dance drawn with known settings (sampling seed 1);
  the search, drawing with seed 0, finds exactly those settings among 24."""
  run = load_run(run_dir)
  reference = list(_drawer(run, 1)(true))
  best, table = search(_drawer(run, 0), reference, run.features.skeleton, run.fps, GRID)
  assert best == true
  assert [s for s, *_ in table[:24]] == [dict(zip(GRID, v)) for v in itertools.product(*GRID.values())]
  assert min(o for *_, o in table) < 0.3  # four measures within ~8% of the reference's


def test_the_grid_drawn_two_at_a_time_is_the_grid_drawn_one_at_a_time(run_dir, monkeypatch):
  """The search draws DRAWS_AT_ONCE settings at once (threads): every row, to the last bit, and its order are what
  drawing them one after another gives."""
  run = load_run(run_dir)
  reference = list(_drawer(run, 1)({"noise_smoothing": 0.85, "sigma_temperature": 1.3}))
  grid = {"noise_smoothing": (0.6, 0.85, 0.95), "sigma_temperature": (0.9, 1.3)}
  tables = {}
  for drawers in (1, 2):
    monkeypatch.setattr(runtime, "DRAWS_AT_ONCE", drawers)
    tables[drawers] = search(_drawer(run, 0), reference, run.features.skeleton, run.fps, grid, beyond={})[1]
  assert runtime.DRAWS_AT_ONCE == 2 and len(tables[1]) == 6
  assert json.dumps(tables[2]) == json.dumps(tables[1])


def test_the_walk_past_the_grid_starts_from_its_three_best_settings(monkeypatch):
  """A constructed landscape (objective by settings): the grid's best has its scale temperature inside the
  grid; its third best sits at the low end, and past it the objective falls below the grid's best. Walking from
  the best alone stops there; walking from the three best finds the lower setting, each setting drawn once."""
  grid = {"noise_smoothing": (0.75, 0.85), "sigma_temperature": (0.9, 1.0, 1.2)}
  values = {(0.85, 1.0): 0.6, (0.85, 0.9): 0.65, (0.75, 0.9): 0.7, (0.75, 0.8): 0.6, (0.75, 0.7): 0.55}
  values |= {(0.75, 0.6): 0.5, (0.75, 0.5): 0.52}
  drawn = []

  def draw(settings):
    drawn.append(settings)
    return values.get((settings["noise_smoothing"], settings["sigma_temperature"]), 1.0)

  monkeypatch.setattr(calibrate, "reference_rates", lambda *a: {})
  monkeypatch.setattr(
    calibrate, "measure", lambda v, rates, root: {**dict.fromkeys(calibrate.RATES, 1.0), "movement": np.exp(v / 2)}
  )
  assert calibrate.objective(calibrate.measure(0.6, {}, 0)) == pytest.approx(0.6)
  beyond = {"sigma_temperature": calibrate.BEYOND["sigma_temperature"]}
  search_ = lambda: search(draw, [], SimpleNamespace(root=0), 30.0, grid, beyond=beyond)
  best, table = search_()
  assert best == {"noise_smoothing": 0.75, "sigma_temperature": 0.6}
  assert len(drawn) == len(table) == len({json.dumps(s, sort_keys=True) for s in drawn})
  monkeypatch.setattr(calibrate, "WALKS", 1)
  assert search_()[0] == {"noise_smoothing": 0.85, "sigma_temperature": 1.0}  # the best's walk alone


@pytest.mark.parametrize("true", [0.7, 1.7])
def test_calibration_goes_past_the_end_of_the_grid_while_the_dance_gets_nearer(run_dir, true):
  """The reference drawn with a sigma temperature outside the grid (0.9-1.2): the best grid value is an end,
  and the search walks the ladder past it (0.8, 0.7, ... or 1.4, 1.7, ...) to the reference's value, and one
  value further, where the objective rises again."""
  run = load_run(run_dir)
  grid = {"noise_smoothing": (0.85,), "sigma_temperature": (0.9, 1.0, 1.2)}
  reference = list(_drawer(run, 1)({"noise_smoothing": 0.85, "sigma_temperature": true}))
  best, table = search(_drawer(run, 0), reference, run.features.skeleton, run.fps, grid)
  assert best == {"noise_smoothing": 0.85, "sigma_temperature": true}
  walked = [s["sigma_temperature"] for s, *_ in table[3:]]
  assert walked[:3] == ([0.8, 0.7, 0.6] if true < 1 else [1.4, 1.7, 2.0])  # from the best
  assert walked[3:] == ([1.4] if true < 1 else [0.8])  # the grid's other end, one step, further off
  at_end, _ = search(_drawer(run, 0), reference, run.features.skeleton, run.fps, grid, beyond={})
  assert at_end["sigma_temperature"] == (0.9 if true < 1 else 1.2)  # without the walk: the grid's end


def test_calibrate_records_the_settings_and_the_run_uses_them_unless_told(run_dir, tmp_path, capsys, small_grid):
  args = ["calibrate", str(run_dir), "--frames", "200", "--num", "2"]
  assert cli.main([*args, "--noise-order", "9"]) == 2 and "sample.noise_order" in capsys.readouterr().err
  assert cli.main([*args, "--pace", "-1"]) == 2 and "sample.pace" in capsys.readouterr().err
  # the smallest search: one 60-frame dancer gave the pose measure one window, a line about --data and --window
  assert cli.main(["calibrate", str(run_dir), "--frames", "60", "--num", "1"]) == 2
  assert "two 60-frame windows" in capsys.readouterr().err
  assert not calibration_path(run_dir).exists()
  assert cli.main([*args, "--noise-order", "4", "--pace", "2"]) == 0
  saved = json.loads(calibration_path(run_dir).read_text())
  chosen = saved["settings"]
  assert set(chosen) == set(CALIBRATED) and saved["reference"] == "training takes"  # a canonical run: feet too
  assert chosen["noise_order"] == 4 and {r["settings"]["noise_order"] for r in saved["table"]} == {4}
  assert chosen["pace"] == 2 and {r["settings"]["pace"] for r in saved["table"]} == {2}  # the run's own is 0.5
  # the grid's 4 settings, then the walk past the end its best noise smoothing is at (of two values, always one)
  out = capsys.readouterr().out
  assert len(saved["table"]) > 4 and out.count("\n") == 1 and out.startswith("calibrated on its training takes")
  assert saved["table"][4]["settings"]["noise_smoothing"] in (0.5, 0.97)
  assert {"movement", "jitter", "speed", "root_travel", "poses", "objective"} <= set(saved["table"][0])
  row = chosen_calibration_row(run_dir)  # what compare ranks calibrated runs by
  assert row is not None and row["settings"] == chosen
  assert row["objective"] == min(r["objective"] for r in saved["table"])
  assert cli.main(args) == 2  # an existing calibration is not replaced without --force
  assert "calibration.json" in capsys.readouterr().err
  out = tmp_path / "s.npz"
  assert cli.main(["sample", str(run_dir), "-o", str(out), "--frames", "30"]) == 0
  assert read_npz(out)[0].num_frames == 30
  with np.load(out) as z:  # what the sample was drawn with
    drawn = json.loads(str(z["meta"]))["settings"]
  assert {k: drawn[k] for k in chosen} == chosen  # the run's default now
  assert load_run(run_dir).sampling(sigma_temperature=0.5).sigma_temperature == 0.5  # a flag still wins
  calibration_path(run_dir).write_text("{not json")
  assert cli.main(["sample", str(run_dir), "-o", str(tmp_path / "t.npz"), "--frames", "30"]) == 2
  assert "damaged calibration" in capsys.readouterr().err
  with pytest.raises(UserError, match="damaged calibration"):
    chosen_calibration_row(run_dir)
  assert cli.main([*args, "--force"]) == 0  # as the refusal says: calibrating again replaces it, unread
  assert chosen_calibration_row(run_dir) is not None
  calibration_path(run_dir).unlink()
  assert chosen_calibration_row(run_dir) is None


def test_a_run_keeps_its_best_checkpoint_and_calibrates_it_when_told(tmp_path, small_grid):
  """train.keep = "best": sample, eval, calibrate and live default to the checkpoint with the lowest
  validation loss (lr 0.3 makes this tiny run's held-out loss rise at the end); train.calibrate: the
  settings are chosen after training, on that checkpoint, and the end sample is drawn with them."""
  w = tmp_path / "run"
  cfg = tiny_config(
    "train.num_steps=40",
    "train.eval_every=10",
    "train.checkpoint_every=40",  # only at the end: the best one is saved where it happens
    "optim.lr=0.3",
    "train.keep=best",
    "train.calibrate=true",
    "log.tensorboard=false",
    "sample.frames=30",
  )
  train_and_evaluate(cfg, w)
  curve = {
    r["step"]: r["val_loss"] for r in map(json.loads, (w / "metrics.jsonl").read_text().splitlines()) if "val_loss" in r
  }
  kept = load_run(w)
  assert kept.step == load_run(w, "best").step == min(curve, key=curve.get) < 40
  assert load_run(w, "latest").step == 40
  settings = json.loads(calibration_path(w).read_text())["settings"]
  assert set(settings) == set(CALIBRATED) - {"foot_lock"}  # not a canonical run: its feet cannot be locked
  assert (w / "samples" / "sample.csv").exists() and (w / "samples" / "player.html").exists()
  config = json.loads((w / "config.json").read_text())
  config["train"]["keep"] = "last"
  (w / "config.json").write_text(json.dumps(config))
  assert load_run(w).step == 40  # keep = "last": the latest


def test_a_resumed_run_keeps_the_best_checkpoint_it_had_before(tmp_path):
  """train.keep = "best" across a resume: orbax held the steps' validation losses in memory only, so a
  resumed run deleted its best step at its first save and kept an over-fitted later one (found on the
  dancers benchmark: a martial run resumed twice kept step 1,500 at held-out NLL 69 over step 250's 39).
  Here one checkpoint besides the best (keep_checkpoints 1), stopped at 30 and resumed to 40."""
  w = tmp_path / "run"
  opts = ["train.eval_every=10", "train.checkpoint_every=10", "train.keep_checkpoints=1", "optim.lr=0.3"]
  opts += ["train.keep=best", "log.tensorboard=false"]
  train_and_evaluate(tiny_config(*opts, "train.num_steps=30"), w)
  train_and_evaluate(tiny_config(*opts, "train.num_steps=40"), w)
  curve = {
    r["step"]: r["val_loss"] for r in map(json.loads, (w / "metrics.jsonl").read_text().splitlines()) if "val_loss" in r
  }
  assert sorted(curve) == [10, 20, 30, 40]
  best = min(curve, key=curve.__getitem__)
  assert best <= 30  # the best came before the resume (lr 0.3: the held-out loss rises after it)
  assert load_run(w).step == best and load_run(w, "latest").step == 40


def test_an_mse_head_calibrates_only_what_can_change_its_dance():
  """An MSE head draws no noise (its frame is its prediction): of the calibrated controls only foot_lock
  can change its dance, and on non-canonical features nothing can (training then skips calibration)."""
  from chorjax.config import load_config
  from chorjax.sampling.calibrate import default_frames, default_grid

  assert set(default_grid(load_config("configs/white.toml"))) == set(CALIBRATED)
  assert default_grid(load_config("configs/white.toml", ["model.head=mse"])) == {"foot_lock": (True, False)}
  assert default_grid(load_config(None, ["model.head=mse", "data.representation=directions"])) == {}
  assert "foot_lock" not in default_grid(load_config(None, ["data.representation=directions"]))
  # an MDN that carries its noise: how wide it draws and whether its feet lock, nothing more
  carried = default_grid(load_config("configs/quickstart.toml", ["model.mdn_memory=2"]))
  assert set(carried) == {"noise_order", "pace", "sigma_temperature", "foot_lock"}
  assert len(carried["sigma_temperature"]) == 8 and carried["foot_lock"] == (True, False)
  # and draws three times as long a dancer (its pose measure is noisy over 1,200 frames)
  assert default_frames(load_config("configs/quickstart.toml", ["model.mdn_memory=2"])) == 3 * 1200
  assert default_frames(load_config("configs/white.toml")) == 1200


def test_a_run_that_carries_its_noise_calibrates_its_temperature_and_feet(tmp_path):
  """``chorjax calibrate`` of a ``model.mdn_memory`` run searches 16 settings and records what it chose."""
  from chorjax.sampling.calibrate import calibrate

  w = tmp_path / "run"
  flags = ["train.num_steps=3", "log.tensorboard=false", "data.representation=canonical", "model.mdn_memory=2"]
  train_and_evaluate(tiny_config(*flags, "model.mdn_basis=acceleration", "sample.clamp=true"), w)
  result = calibrate(w, frames=240, num=1, log=lambda line: None)
  assert set(result["settings"]) == {"noise_order", "pace", "sigma_temperature", "foot_lock"}
  assert len(result["table"]) >= 16 and {r["settings"]["foot_lock"] for r in result["table"]} == {True, False}
  assert load_run(w).sampling().sigma_temperature == result["settings"]["sigma_temperature"]


def test_the_pose_measure_holds_real_takes_near_one_and_a_frozen_dancer_far_from_it():
  """``poses`` on real cmu94 takes: the held-out takes score near the training takes' own halves; a dancer
  frozen in one of their poses scores far worse; the training takes themselves score nearest."""
  from chorjax.data.dataset import load_dataset
  from chorjax.evaluation.scoring import PoseDistribution

  ds = load_dataset(tiny_config().data)
  y_up = lambda m: np.asarray(to_y_up(m.positions, ds.features.up_axis))
  train = [y_up(m) for m in ds.motions if m.name in ds.train_names]
  held = [y_up(m) for m in ds.motions if m.name in ds.val_names]
  poses = PoseDistribution(train, ds.features.skeleton)
  real = poses.ratio(held)
  assert 0.5 < real < 2.0
  assert poses.ratio([np.repeat(held[0][:1], 600, 0)]) > 2 * real  # one pose, held
  assert poses.ratio(train) < real  # the training takes themselves are nearest


def test_the_governor_holds_what_the_judge_measures_turning_included(run_dir):
  """A canonical run records its training takes' pace as ``metrics.displacement`` measures a dance (joints
  relative to the root, turning included: ``Features.pace_joints``), and the governor holds the dancer to it
  by that measure: told half or twice the free dancer's pace, it holds back or pushes on."""
  from chorjax.data.dataset import load_dataset
  from chorjax.data.features import Features, take_joint_pace
  from chorjax.evaluation.metrics import displacement
  from chorjax.families.recurrent.generation import generate

  run = load_run(run_dir)
  f, m, lag = run.features, run.features.joint_motion, run.features.pace_lag
  assert m is not None and Features.from_dict(f.to_dict()).pace_joints == f.pace_joints  # saved with the run

  pace_of = lambda z_TxD: take_joint_pace(z_TxD, lag, m)
  train = [x for _, x in load_dataset(run.config.data).train]
  judged = [displacement(np.asarray(f.canonical(f.decode(x))), f.skeleton.root, lag) for x in train[:3]]
  np.testing.assert_allclose([pace_of(x).mean() for x in train[:3]], judged, rtol=1e-4)  # the judge's own measure
  assert f.pace_joints == pytest.approx(np.concatenate([pace_of(x) for x in train]).mean(), rel=1e-5)
  assert any(np.abs(x[:, 0]).max() > 0.01 for x in train)  # the takes turn, so turning counts
  gen = lambda **kw: np.asarray(
    generate(
      run.graphdef,
      run.params,
      np.arange(4) % 2,
      jax.random.key(0),
      num_frames=400,
      draw=Draw(noise_smoothing=0.5, **kw),
    )
  )
  settled = lambda z: np.mean([pace_of(d[200:]).mean() for d in z])  # once the running mean settled
  free = settled(gen())
  held = lambda ref: settled(gen(pace=2.0, pace_lag=lag, pacing=Pacing(ref, joints=m)))
  assert held(0.5 * free) < 0.9 * free < 0.9 * held(2 * free)  # held back, left alone, pushed on


def test_calibration_measures_a_dance_as_the_judge_does():
  """The four rates calibration matches are ``chorjax eval``'s, reference pooled over its frames: on cmu94's
  training takes (unequal lengths) a stretch of a held-out take gets the same movement, jitter, speed and root
  travel from both. (Calibration once averaged speed and travel per take: martial's short, fast training takes
  then weighed as much as its long ones, and a dancer calibrated to speed 1.15 was judged 1.25.)"""
  from chorjax.data.dataset import load_dataset
  from chorjax.evaluation.scoring import score

  ds = load_dataset(tiny_config().data)
  f = ds.features
  y_up = lambda m: np.asarray(to_y_up(m.positions, f.up_axis), np.float64)
  train = [y_up(m) for m in ds.motions if m.name in ds.train_names]
  assert len({len(t) for t in train}) > 1  # unequal lengths: pooled and per-take means differ
  dancer = y_up(next(m for m in ds.motions if m.name in ds.val_names))[:600]
  judged = score([dancer], train, f.skeleton, ds.fps, segment=600)
  measured = calibrate.measure(dancer[None], calibrate.reference_rates(train, f.skeleton, ds.fps), f.skeleton.root)
  judge = {"movement": "movement_first", "jitter": "jitter", "speed": "speed", "root_travel": "root_travel"}
  assert set(judge) == set(calibrate.RATES)
  for key, name in judge.items():  # one segment of 600 frames: the judge's first is the whole dance
    assert measured[key] == pytest.approx(judged[name], rel=1e-6), key


def test_an_evaluation_over_seeds_drawn_side_by_side_is_the_one_drawn_seed_after_seed(run_dir, monkeypatch):
  """``chorjax eval --seeds``' draws run side by side (``runtime.side_by_side``, as calibration's): every
  figure and the first dancer are what drawing the seeds one after another gives."""
  from chorjax.evaluation.evaluate import evaluate

  results = {}
  for drawers in (1, 2):
    monkeypatch.setattr(runtime, "DRAWS_AT_ONCE", drawers)
    results[drawers] = evaluate(run_dir, ["cmu94"], frames=200, num=2, seeds=[0, 1, 2], splits=2)
  first = {k: results[k].pop("first_sample").positions for k in results}
  assert np.array_equal(first[1], first[2])
  assert json.dumps(results[2], sort_keys=True) == json.dumps(results[1], sort_keys=True)
  assert set(results[1]["fid_k"]) == {"mean", "sd"} and results[1]["fid_k"]["sd"] > 0  # three seeds, three draws
