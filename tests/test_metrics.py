"""Metrics on constructed cases and real takes; eval, sweep and compare end to end (tiny)."""

import json

import numpy as np
import pytest
import scipy.linalg
from helpers import TINY

from chorjax import cli
from chorjax.config import load_config
from chorjax.data import transforms as tf
from chorjax.data.csv import read_csv
from chorjax.data.dataset import bundled_path, load_dataset, read_takes
from chorjax.data.motion import bone_length_cv
from chorjax.data.skeletons import MPII16
from chorjax.evaluation import metrics as M
from chorjax.evaluation.evaluate import held_out
from chorjax.evaluation.reports import WHERE_MEASURED, metric_keys
from chorjax.evaluation.scoring import mean_of, score

TAKE = read_csv(bundled_path("cmu94") / "94_05_skeleton_3d.csv")
POS = np.asarray(tf.rotate(TAKE.positions, tf.up_axis_matrix("-y")))  # y-up


def test_speed_ratio_zero_for_a_frozen_sequence_and_one_for_the_data():
  frozen = np.repeat(POS[:1], 500, axis=0)
  speed = M.joint_speed(POS).mean()
  assert M.speed_ratio(frozen, speed) == 0.0
  assert M.speed_ratio(POS, speed) == pytest.approx(1.0)


def test_bone_cv_zero_for_a_rigidly_turning_and_moving_skeleton():
  pose = POS[0]
  t = np.linspace(0, 3, 200)
  rot = np.stack([np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]]) for a in t])
  rigid = np.einsum("tij,kj->tki", rot, pose) + t[:, None, None] * 10
  r = score([rigid], [POS], MPII16, 30.0, splits=2, window=30)
  assert r["bone_cv_mean"] < 1e-6 and r["bone_cv_max"] < 1e-6
  assert np.median(bone_length_cv(POS, MPII16)) <= 0.03


def test_foot_sliding_measures_horizontal_speed_on_the_ground():
  pose = POS[0].copy()
  pose[:, 1] -= pose[list(MPII16.feet), 1].min()  # feet on the floor
  planted = np.repeat(pose[None], 120, axis=0)
  size = M.body_size(POS, MPII16)
  assert M.foot_sliding(planted, MPII16, 30.0, size) == 0.0
  slide = planted.copy()
  slide[:, :, 0] += np.arange(120)[:, None] * (0.3 * size / 30.0)  # the whole body glides at 0.3 sizes/s
  assert M.foot_sliding(slide, MPII16, 30.0, size) == pytest.approx(0.3, rel=1e-4)


def loop_kinetic(p, fps, w=2):
  """The AIST++ definitions, frame by frame, with the acceleration's parenthesis fixed."""
  t, dt, out = len(p), 1.0 / fps, []
  for j in range(p.shape[1]):
    kh = kv = ee = 0.0
    for i in range(1, t):
      v, n = np.zeros(3), 0
      for k in range(-w, w + 1):
        if i + k - 1 >= 0 and i + k < t:
          v, n = v + p[i + k, j] - p[i + k - 1, j], n + 1
      v = v / (n * dt)
      kh, kv = kh + v[0] ** 2 + v[2] ** 2, kv + v[1] ** 2
      a, n = np.zeros(3), 0
      for k in range(-w, w + 1):
        if i + k - 1 >= 0 and i + k + 1 < t:
          a, n = a + ((p[i + k + 1, j] - p[i + k, j]) / dt - (p[i + k, j] - p[i + k - 1, j]) / dt) / dt, n + 1
      ee += np.linalg.norm(a / n) if n else 0.0
    out += [kh / (t - 1), kv / (t - 1), ee / (t - 1)]
  return np.array(out)


def test_kinetic_features_equal_the_frame_by_frame_definition():
  p = POS[:50, :6].astype(np.float64) / 300.0
  np.testing.assert_allclose(M.kinetic_features(p, 30.0), loop_kinetic(p, 30.0), rtol=1e-9, atol=1e-12)
  assert M.kinetic_features(POS, 30.0).shape == (48,)


def test_fid_and_diversity_against_independent_computations():
  rng = np.random.default_rng(0)
  a, b = rng.normal(size=(200, 6)), rng.normal(size=(150, 6)) @ rng.normal(size=(6, 6)) + 1.0
  sa, sb = np.cov(a, rowvar=False), np.cov(b, rowvar=False)
  want = np.sum((a.mean(0) - b.mean(0)) ** 2) + np.trace(sa + sb - 2 * np.real(scipy.linalg.sqrtm(sa @ sb)))
  assert M.frechet_distance(a, b) == pytest.approx(want, rel=1e-6)
  assert abs(M.frechet_distance(a, a)) < 1e-9  # identical sets
  brute = np.mean([np.linalg.norm(x - y) for i, x in enumerate(b) for j, y in enumerate(b) if i != j])
  assert M.diversity(b) == pytest.approx(brute, rel=1e-9)
  feats = np.stack([M.kinetic_features(w, 30.0) for w in M.windows(POS / 300, 60, 30)])
  feats = (feats - feats.mean(0)) / feats.std(0)
  assert abs(M.frechet_distance(feats, feats)) < 1e-4  # round-off against a covariance trace of ~48


def test_novelty_zero_for_a_copied_window_and_positive_otherwise():
  train = M.windows(POS, 60, 10)
  assert M.novelty(train[3:5], train, MPII16.root) == pytest.approx(0.0, abs=1e-3)
  other = read_csv(bundled_path("cmu94") / "94_10_skeleton_3d.csv").positions
  held = M.windows(np.asarray(tf.rotate(other, tf.up_axis_matrix("-y"))), 60, 30)
  assert M.novelty(held, train, MPII16.root) > 1.0


# ---------------------------------------------------------------- eval, sweep, compare


def test_a_sweep_knows_a_run_sized_by_epochs_or_ended_by_patience_is_finished(tmp_path):
  """A point trained with `train.epochs` ends at the step its own config.json resolved (not the sweep's
  num_steps), and one that `train.patience` ended early has its end-of-run sample: neither is trained again."""
  from chorjax.sweeps import is_finished

  sized, ended, stopped = (tmp_path / n for n in ("sized", "ended", "stopped"))
  for run, step in ((sized, 3514), (ended, 750), (stopped, 750)):
    (run / "checkpoints" / str(step)).mkdir(parents=True)
    (run / "config.json").write_text(json.dumps({"train": {"num_steps": 3514 if run == sized else 2000}}))
  (ended / "samples").mkdir()
  (ended / "samples" / "sample.csv").write_text("x")
  assert is_finished(sized, 2000, False) and is_finished(ended, 2000, False)
  assert not is_finished(stopped, 2000, False)  # stopped by a signal: resumed
  assert not is_finished(sized, 2000, True)  # trained, not evaluated yet


def test_sweep_eval_compare_end_to_end(tmp_path, monkeypatch, capsys):
  monkeypatch.chdir(tmp_path)
  set_lines = "\n".join(
    f'"{k}" = {v if v.replace(".", "").replace("-", "").isdigit() or v in ("true", "false") else json.dumps(v)}'
    for k, v in (o.split("=", 1) for o in TINY)
  )
  (tmp_path / "base.toml").write_text("")
  sweep = tmp_path / "s.toml"
  sweep.write_text(
    'name = "t"\nbase = "base.toml"\nvectorize = ["train.seed"]\n'
    f'[grid]\n"model.head" = ["mdn", "mse"]\n"train.seed" = [0, 1]\n'
    f'[set]\n{set_lines}\n"log.tensorboard" = false\n'
    '[eval]\ndata = ["held-out"]\nframes = 240\nnum = 1\nseeds = [0, 1]\nsplits = 3\n'
  )
  assert cli.main(["sweep", str(sweep), "--shard", "0/2"]) == 0  # two jobs of an array, no coordinator
  # the seeds of one head trained together (vectorize), as one group of the shard
  assert sorted(r.name for r in (tmp_path / "runs" / "t").iterdir()) == ["t-head=mdn-seed=0", "t-head=mdn-seed=1"]
  assert "t-head=mdn-seed=0, t-head=mdn-seed=1: training together" in capsys.readouterr().out
  assert cli.main(["sweep", str(sweep), "--shard", "1/2"]) == 0
  with pytest.raises(SystemExit, match="2"):  # argparse: one usage line, exit 2
    cli.main(["sweep", str(sweep), "--shard", "2/2"])
  runs = sorted((tmp_path / "runs" / "t").iterdir())
  assert [r.name for r in runs] == ["t-head=mdn-seed=0", "t-head=mdn-seed=1", "t-head=mse-seed=0", "t-head=mse-seed=1"]
  m = json.loads((runs[0] / "eval" / "metrics.json").read_text())
  for key in (
    "heldout_loss",
    *(k for k in metric_keys() if k not in WHERE_MEASURED),  # not single-take: nine takes, five minutes
    "fid_k_real",
    "fid_g_real",
    "novelty_real",
    "fid_k_train",
    "fid_g_train",
    "movement_min_train",
  ):
    assert np.isfinite(mean_of(m[key])), key
  assert all(m[k] is None for k in WHERE_MEASURED)
  assert m["data"] == ["held-out"]  # judged on the run's own held-out take (94_10) alone
  assert set(m["fid_k"]) == {"mean", "sd"} and set(m["movement_first"]) == {"mean", "sd"}  # 2 seeds
  each = m["per_motion"]  # every sample's own value of the per-sample bars, the keys' mean and sd over them
  assert len(each["movement_min"]) == len(each["root_step_max"]) == 2
  assert np.mean(each["movement_min"]) == pytest.approx(m["movement_min"]["mean"])
  assert np.mean(each["root_step_max"]) == pytest.approx(m["root_step_max"]["mean"])
  assert m["sampling"]["seeds"] == [0, 1] and (runs[0] / "eval" / "sample.npz").exists()
  assert m["loss_takes"] == "held-out"  # 94_10: the take the runs' split held out
  assert m["loss_kind"] == "nll" and json.loads((runs[2] / "eval" / "metrics.json").read_text())["loss_kind"] == "mse"
  capsys.readouterr()
  assert cli.main(["sweep", str(sweep)]) == 0  # finished points are skipped
  assert capsys.readouterr().out.count("finished, skipped") == 4
  report = tmp_path / "report.md"
  assert cli.main(["compare", *map(str, runs), "-o", str(report)]) == 0
  text = report.read_text()
  assert "| t-head=mdn | 2 | lnlstm | mdn |" in text and "| t-head=mse | 2 | lnlstm | mse |" in text  # seeds grouped
  assert "## Who wins" in text and "not comparable" in text and " ± " in text and "(incl. training takes)" not in text
  assert m["segment_frames"] == 240 and "Evaluation of every run: 1 x 240 frames" in text  # what was measured
  assert "segments of 240 frames" in text and "movement first segment" in text
  row = next(line for line in text.splitlines() if line.startswith("| t-head=mdn |")).split(" | ")
  header = next(line for line in text.splitlines() if line.startswith("| config |")).split(" | ")
  assert " ± " in row[header.index("FID_k / train takes'")] and " ± " in row[header.index("root travel")]
  assert (tmp_path / "report_strip0.png").exists() and "![t-head=mse](report_strip1.png)" in text
  assert (tmp_path / "report_loss.png").exists() and (tmp_path / "report_movement.png").exists()
  assert "Chosen from the training takes alone" not in text  # no run was calibrated
  # calibrated runs: the report names the one whose draws came nearest its own training takes
  from chorjax.sampling.calibrate import calibrate

  objective = {}
  for run, rho in ((runs[0], 0.9), (runs[1], 0.0)):  # smooth draws and white noise: different distances
    cal = calibrate(run, frames=240, num=2, grid={"noise_smoothing": (rho,)}, log=lambda _: None)
    objective[run.name] = cal["table"][0]["objective"]
  assert objective["t-head=mdn-seed=0"] != objective["t-head=mdn-seed=1"]
  assert cli.main(["compare", *map(str, runs), "-o", str(tmp_path / "chosen.md")]) == 0
  chosen = next(l for l in (tmp_path / "chosen.md").read_text().splitlines() if "Chosen from the training" in l)
  best = min(objective, key=objective.__getitem__)
  assert f"**Chosen from the training takes alone**: {best} (t-head=mdn)" in chosen
  assert f"of 2 calibrated runs ({objective[best]:.2f};" in chosen
  # eval through the CLI, and its errors
  assert (
    cli.main(
      [
        "eval",
        str(runs[0]),
        "--data",
        "cmu94/94_10_skeleton_3d.csv",
        "--frames",
        "240",
        "--num",
        "1",
        "-o",
        str(tmp_path / "m.json"),
      ]
    )
    == 0
  )
  m = json.loads((tmp_path / "m.json").read_text())
  assert (m["frames"], m["num"], m["data"]) == (240, 1, ["cmu94/94_10_skeleton_3d.csv"])
  again = ["eval", str(runs[0]), "--data", "cmu94/94_10_skeleton_3d.csv", "--frames", "120", "--num", "1"]
  assert cli.main([*again, "-o", str(tmp_path / "m3.json")]) == 0  # a second evaluation in the same folder
  assert (tmp_path / "m.sample.npz").is_file() and (tmp_path / "m3.sample.npz").is_file()
  assert mean_of(m["fid_k"]) >= 0 and mean_of(m["fid_k_real"]) >= 0 and m["div_k"] > 0
  assert np.isfinite(m["heldout_loss"])
  assert cli.main(["eval", str(runs[0]), "--data", "nope.csv", "-o", str(tmp_path / "m2.json")]) == 2
  assert cli.main(["compare", str(tmp_path), "-o", str(tmp_path / "r2.md")]) == 2
  # one run re-evaluated otherwise: the report says which run was measured how
  args = ["eval", str(runs[1]), "--data", "cmu94/94_10_skeleton_3d.csv", "--frames", "300", "--num", "1", "--force"]
  assert cli.main(args) == 0
  assert cli.main(["compare", *map(str, runs), "-o", str(tmp_path / "r3.md")]) == 0
  text = (tmp_path / "r3.md").read_text()
  assert "Evaluation settings differ between runs:" in text and "- t-head=mdn-seed=1: 1 x 300 frames" in text
  # runs over several datasets: a table and winners per dataset (copies of the MSE runs, told another dataset)
  import shutil

  others = []
  for r in runs[2:]:
    o = tmp_path / "other" / r.name.replace("t-", "o-", 1)
    shutil.copytree(r, o)
    cfg = json.loads((o / "config.json").read_text())
    cfg["data"]["dataset"] = "salsa-takes"
    (o / "config.json").write_text(json.dumps(cfg))
    others.append(o)
  assert cli.main(["compare", *map(str, runs), *map(str, others), "-o", str(tmp_path / "datasets.md")]) == 0
  text = (tmp_path / "datasets.md").read_text()
  cmu94, salsa = text.index("## Dataset: cmu94"), text.index("## Dataset: salsa-takes")
  assert "Runs on 2 datasets" in text and text.count("### Who wins") == 2
  assert cmu94 < text.index("| t-head=mse | 2 |") < salsa < text.index("| o-head=mse | 2 |")
  assert "| o-head" not in text[cmu94:salsa] and "| t-head" not in text[salsa : text.index("## What the models")]
  # an evaluation from before loss_takes measured the loss on every --data take: marked, and not ranked
  legacy = runs[2] / "eval" / "metrics.json"
  legacy.write_text(json.dumps({k: v for k, v in json.loads(legacy.read_text()).items() if k != "loss_takes"}))
  assert cli.main(["compare", *map(str, runs[2:]), "-o", str(tmp_path / "r4.md")]) == 0
  text = (tmp_path / "r4.md").read_text()
  assert "(incl. training takes) |" in text and "not comparable (some on held-out takes" in text


# ---------------------------------------------------------------- movement, jitter, bones, FID on constructed cases


@pytest.fixture(scope="module")
def takes():
  """The cmu94 takes, y-up, by name."""
  from chorjax.data.dataset import resolve_files

  return {f.stem: np.asarray(tf.to_y_up(read_csv(f).positions, "-y"), np.float64) for f in resolve_files("cmu94")}


def _score(motion, takes, held="94_10_skeleton_3d"):
  return score([motion], [t for n, t in takes.items() if n != held], MPII16, 30.0, splits=5)


def test_an_unseen_real_take_scores_like_the_data_and_so_do_its_mirror_and_reversal(takes):
  take = takes["94_10_skeleton_3d"]
  for motion in (take, np.asarray(tf.mirror(take, MPII16.twins)), take[::-1]):
    r = _score(motion, takes)
    assert 0.8 <= r["movement_first"] <= 1.25 and 0.8 <= r["jitter"] <= 1.25, r
    for k in ("fid_k", "fid_g"):  # inside the real reference's own spread
      assert r[k]["mean"] <= r[k + "_real"]["mean"] + 2 * r[k + "_real"]["sd"], (k, r[k], r[k + "_real"])


def test_a_held_pose_that_trembles_scores_as_trembling(takes):
  take = takes["94_10_skeleton_3d"]
  fake = np.repeat(take[100:101], 3000, 0) + np.random.default_rng(0).normal(0, 1.0, (3000, 16, 3))
  r = _score(fake, takes)
  assert r["movement_max"] < 0.2 and r["jitter"] > 2
  teleport = fake.copy()
  teleport[1500:] += np.array([300.0, 0.0, 0.0])  # the whole body jumps 300 units (a thigh is ~94) in one frame
  assert _score(fake, takes)["root_step_max"] < 1 < 1.5 < _score(teleport, takes)["root_step_max"]
  # the old frame-to-frame speed ratio counts the trembling as movement: why it is no freeze measure
  assert r["speed_ratio"] > 4 * r["movement_max"]
  for k in ("fid_k", "fid_g"):  # far outside the real spread
    assert r[k]["mean"] > r[k + "_real"]["mean"] + 4 * r[k + "_real"]["sd"], (k, r[k], r[k + "_real"])


def test_movement_per_segment_sees_a_dance_that_stops():
  rng = np.random.default_rng(0)
  walk = np.cumsum(rng.normal(0, 1, (2000, 16, 3)), 0)
  stopped = np.concatenate([walk, np.repeat(walk[-1:], 2000, 0)])
  r = score([stopped], [walk], MPII16, 30.0, splits=2, window=30)
  curve = r["movement_curve"]
  assert len(curve) == 4 and curve[0] == pytest.approx(1.0, rel=0.1) and curve[-1] == 0.0
  assert r["movement_first"] == curve[0] and r["movement_last"] == 0.0 and r["movement_min"] == 0.0


def test_rigid_bones_have_zero_cv_and_the_mean_and_max_see_one_bad_bone(takes):
  take = takes["94_10_skeleton_3d"]
  rigid = np.repeat(take[:1], 200, 0) + np.linspace(0, 50, 200)[:, None, None]  # translated, never bent
  r = score([rigid], [take], MPII16, 30.0, splits=2, window=30)
  assert r["bone_cv_mean"] < 1e-9 and r["bone_cv_max"] < 1e-9
  stretched = rigid.copy()
  stretched[:, 0] += np.sin(np.arange(200))[:, None] * 10  # the right foot wobbles
  r = score([stretched], [take], MPII16, 30.0, splits=2, window=30)
  assert r["bone_cv_max"] > 0.05 and r["bone_cv_median"] < 1e-9 and r["bone_cv_mean"] > 0


def test_chorjax_metrics_separates_a_real_take_from_a_trembling_fake(tmp_path, takes, capsys):
  from chorjax.data.csv import write_csv

  take = read_csv(bundled_path("cmu94") / "94_10_skeleton_3d.csv").positions
  fake = np.repeat(take[100:101], 3000, 0) + np.random.default_rng(0).normal(0, 1.0, (3000, 16, 3)).astype(np.float32)
  write_csv(fake, tmp_path / "fake.csv")
  refs = [str(f) for f in sorted(bundled_path("cmu94").glob("94_0*.csv"))]
  out = {}
  for name, path in (("real", bundled_path("cmu94") / "94_10_skeleton_3d.csv"), ("fake", tmp_path / "fake.csv")):
    assert cli.main(["metrics", str(path), "--data", *refs, "--splits", "5", "-o", str(tmp_path / f"{name}.json")]) == 0
    out[name] = json.loads((tmp_path / f"{name}.json").read_text())
  keys = set(  # issue 14's list, verbatim
    "movement_first movement_last movement_min movement_max jitter jitter_max bone_cv_mean bone_cv_max "
    "fid_k fid_k_real div_k fid_g fid_g_real div_g pfc foot_sliding novelty novelty_real".split()
  )
  assert keys <= set(out["real"]) and keys <= set(out["fake"])
  real, fake = out["real"], out["fake"]
  assert 0.8 <= real["movement_min"] <= 1.25 and fake["movement_max"] < 0.2
  assert 0.8 <= real["jitter"] <= 1.25 and fake["jitter"] > 2
  for k in ("fid_k", "fid_g"):  # the real take inside the data's own spread, the fake far outside it
    ref = real[k + "_real"]
    assert real[k]["mean"] <= ref["mean"] + 2 * ref["sd"] < ref["mean"] + 3 * ref["sd"] < fake[k]["mean"], k
  assert "movement_min" in capsys.readouterr().out
  assert cli.main(["metrics", str(tmp_path / "nope.csv"), "--data", *refs]) == 2


def test_sweep_candidates_cross_the_grid_and_bad_keys_are_named(tmp_path):
  from chorjax.sweeps import load_sweep, sweep_points

  path = tmp_path / "s.toml"
  path.write_text(
    'name = "lh"\n[grid]\n"train.seed" = [0, 1]\n[set]\n"train.num_steps" = 5\n'
    '[candidates.base]\n[candidates.auto]\n"train.feedback" = "auto"\n"data.representation" = "canonical"\n'
  )
  points = sweep_points(load_sweep(path))
  assert [n for n, _ in points] == ["lh-base-seed=0", "lh-base-seed=1", "lh-auto-seed=0", "lh-auto-seed=1"]
  assert points[3][1] == [
    "train.num_steps=5",
    'train.feedback="auto"',
    'data.representation="canonical"',
    "train.seed=1",
  ]
  path.write_text('[grid]\n"train.seed" = [0]\n[candidates.x]\n"train.feedbak" = "auto"\n')
  from chorjax.errors import UserError

  with pytest.raises(UserError, match=r"\[candidates.x\] key 'train.feedbak' is not a config key"):
    load_sweep(path)


def test_older_metrics_files_state_the_controls_added_since_as_off():
  """Runs evaluated before a sampling control existed group with runs that state it off (compare)."""
  from chorjax.compare import group_runs, upgrade

  old = {"movement_first_1000": 0.5, "sampling": {"pi_temperature": 0.2, "seed": 0}}
  new = {"movement_first": 0.5, "sampling": {"pi_temperature": 0.2, "clamp": False, "pace": 0.0, "seed": 0}}
  up = upgrade(old)
  assert up["movement_first"] == 0.5 and up["sampling"]["clamp"] is False and up["sampling"]["pace"] == 0.0
  assert up["sampling"]["pi_temperature"] == 0.2  # what the file says wins
  cfg = {"train": {"seed": 0}, "model": {}}
  runs = [
    {"name": f"x-seed={s}", "config": {**cfg, "train": {"seed": s}}, "eval": upgrade(e)}
    for s, e in enumerate([old, new])
  ]
  assert len(group_runs(runs)) == 1
  runs[1]["eval"]["sampling"]["pace"] = 0.5  # a control really on is another group
  assert len(group_runs(runs)) == 2
  runs[1]["eval"]["sampling"]["pace"] = 0.0
  runs[1]["name"] = "y-seed=1"  # the same config under another name is another row
  assert [g["name"] for g in group_runs(runs)] == ["x-seed=0", "y-seed=1"]


def test_the_held_out_loss_is_measured_on_the_takes_the_run_did_not_train_on():
  split = load_dataset(load_config(None, ["data.seq_length=20"]).data)
  takes = read_takes(["cmu94"])
  scored, kind = held_out(takes, split.train_names)
  assert kind == "held-out" and [m.name for m in scored] == list(split.val_names) == ["94_10_skeleton_3d"]
  own = [m for m in takes if m.name in split.train_names]
  scored, kind = held_out(own, split.train_names)  # nothing held out: the loss on the run's own takes, said so
  assert kind == "all" and [m.name for m in scored] == [m.name for m in own] and len(own) == 9


def test_the_training_takes_are_the_reference_held_out_figures_are_held_against(takes):
  """fid_*_train: the run's training takes scored as a sample against the held-out takes, the same
  ruler as a sample (passing those takes as the motions gives the same figure); speed and root travel
  are 1 for the held-out takes themselves and 0 for a dancer frozen on the spot."""
  held = ["94_09_skeleton_3d", "94_10_skeleton_3d"]
  train = [t for n, t in takes.items() if n not in held]
  unseen = [takes[n] for n in held]
  r = score(train, unseen, MPII16, 30.0, train=train, unseen=unseen, splits=5)
  for k in ("fid_k", "fid_g"):
    assert r[f"{k}_train"] == r[k], k  # the same windows, splits and seed
    assert r[f"{k}_train"]["mean"] > r[f"{k}_real"]["mean"] > 0  # other takes differ more than halves
  lag = 15  # half a second at 30 fps
  ref, _ = M.reference_rates(unseen, MPII16.root, lag)
  each = [
    M.displacement(t, MPII16.root, lag) / ref for t in train
  ]  # each cmu94 take is under 2,000 frames: one segment
  assert r["movement_min_train"] == pytest.approx(min(each)) and r["movement_max_train"] == pytest.approx(max(each))
  # the dancer's own takes stray from the held-out takes' movement: one training take is calmer than 0.7 of it
  assert r["movement_min_train"] < 0.7 < 1.1 < r["movement_max_train"]
  same = score(unseen, unseen, MPII16, 30.0, splits=5)
  assert same["fid_k_train"] is None and same["movement_min_train"] is None  # no training takes: no such reference
  assert same["speed"] == pytest.approx({"mean": 1.0, "sd": same["speed"]["sd"]}, rel=0.3)
  assert np.mean([same["root_travel"]["mean"]]) == pytest.approx(1.0, rel=0.3)
  frozen = np.repeat(unseen[0][:1], 600, axis=0)
  still = score([frozen], unseen, MPII16, 30.0, splits=5)
  assert still["speed"] == 0.0 and still["root_travel"] == 0.0


def test_airborne_is_near_zero_for_real_dance_and_counts_the_frames_a_dancer_floats(takes):
  size = M.body_size(takes["94_10_skeleton_3d"], MPII16)
  for name, take in takes.items():
    assert M.airborne(take, MPII16, size) < 0.01, name  # real dance keeps a foot on the floor
  take = takes["94_10_skeleton_3d"].copy()
  lifted = np.zeros(len(take), bool)
  lifted[100:300] = True  # 200 frames carried 0.2 body sizes up: floating
  take[lifted, :, 1] += 0.2 * size
  assert M.airborne(take, MPII16, size) == pytest.approx(lifted.mean(), abs=0.01)
  r = _score(take, takes)
  assert r["airborne"] == pytest.approx(lifted.mean(), abs=0.01) and r["airborne_real"] < 0.01


# ---------------------------------------------------------------- the single-take measures


def _cmu94(n: int) -> np.ndarray:
  from chorjax.data.csv import read_csv
  from chorjax.data.dataset import bundled_path
  from chorjax.data.transforms import to_y_up

  m = read_csv(bundled_path("cmu94") / f"94_{n:02d}_skeleton_3d.csv")
  return np.asarray(to_y_up(m.positions, m.up_axis), np.float64)


def test_patched_cost_is_the_least_cost_cut_into_long_enough_pieces():
  """``global_diversity``'s dynamic programme equals trying every cut of the rows into pieces of at least
  ``shortest`` frames, each matched along a diagonal of the columns within one take."""
  import functools

  from chorjax.evaluation.single_take import patched_cost

  rng = np.random.default_rng(0)
  for t, u, shortest, starts in ((7, 5, 2, (0,)), (9, 6, 3, (0, 3)), (8, 8, 1, (0, 2, 5))):
    cost = rng.random((t, u))
    take_of = np.searchsorted(np.array(starts), np.arange(u), side="right")

    @functools.cache
    def best(i: int, t=t, u=u, shortest=shortest, take_of=take_of, cost=cost) -> float:  # rows i.. cut into pieces
      if i == t:
        return 0.0
      out = np.inf
      for end in range(i + shortest, t + 1):
        for k in range(u - (end - i) + 1):
          if take_of[k] == take_of[k + end - i - 1]:
            out = min(out, sum(cost[i + d, k + d] for d in range(end - i)) + best(end))
      return out

    assert patched_cost(cost, shortest, starts) == pytest.approx(best(0) / t)


def test_single_take_measures_tell_a_replay_a_variation_and_another_dance_apart():
  """On cmu94: the take itself is covered whole with no diversity; the take danced 10% faster is covered
  whole and barely diverse; another take of the dancer covers none of it and is far; a frozen pose covers
  nothing; two samples that are one dance have no diversity between them."""
  from chorjax.data.skeletons import MPII16
  from chorjax.data.transforms import resample
  from chorjax.evaluation import metrics
  from chorjax.evaluation.single_take import KEYS, single_take

  take, other = _cmu94(1), _cmu94(2)
  size = metrics.body_size(take, MPII16)
  same = single_take([take, take], [take], MPII16, size)
  assert tuple(same) == KEYS  # what eval and metrics write (null where not measured)
  assert same["coverage"] == 1.0 and same["global_diversity"] == pytest.approx(0.0, abs=1e-6)
  assert same["local_diversity"] == pytest.approx(0.0, abs=1e-6) and same["inter_diversity"] == pytest.approx(
    0, abs=1e-6
  )
  faster = np.asarray(resample(take, 30.0, 27.0), np.float64)
  varied = single_take([faster, other], [take], MPII16, size)
  assert varied["coverage"] == 0.5 and varied["coverage_together"] == 1.0  # the faster one covers it all
  alone = single_take([other], [take], MPII16, size)
  assert alone["coverage"] == 0.0 and alone["inter_diversity"] is None
  assert 0 < single_take([faster], [take], MPII16, size)["global_diversity"] < 0.1 < 0.3 < alone["global_diversity"]
  assert varied["inter_diversity"] > 0.3
  frozen = single_take([np.repeat(take[:1], 600, 0)], [take], MPII16, size)
  assert frozen["coverage"] == 0.0


def test_chorjax_metrics_reports_the_single_take_measures_against_a_short_reference(tmp_path, capsys):
  from chorjax import cli
  from chorjax.data.csv import read_csv, write_csv
  from chorjax.data.dataset import bundled_path
  from chorjax.data.transforms import resample

  m = read_csv(bundled_path("cmu94") / "94_01_skeleton_3d.csv")
  write_csv(m.replace(positions=np.asarray(resample(m.positions, 30.0, 27.0), np.float32)), tmp_path / "fast.csv")
  args = ["metrics", str(tmp_path / "fast.csv"), "--data"]
  assert cli.main([*args, str(bundled_path("cmu94") / "94_01_skeleton_3d.csv"), "-o", str(tmp_path / "a.json")]) == 0
  said = capsys.readouterr().out
  assert "coverage" in said and "global_diversity" in said and "inter_diversity" not in said  # one sample
  assert json.loads((tmp_path / "a.json").read_text())["coverage"] == 1.0
  assert cli.main([*args, "cmu94", "-o", str(tmp_path / "b.json")]) == 0  # ten takes, 5 minutes: not one take
  assert "coverage" not in capsys.readouterr().out
  assert json.loads((tmp_path / "b.json").read_text())["coverage"] is None


def test_a_metric_is_one_function_and_one_registration(tmp_path, capsys):
  """A metric registered with ``@metric`` is measured by ``score``, written by ``chorjax metrics`` and ``chorjax
  eval`` and printed in its place; the docs' table is the registry's (every metric's name, printed keys and
  first docstring line)."""
  from pathlib import Path

  from chorjax.evaluation import scoring

  @scoring.metric("stillness", "stillness")
  def stillness(j):
    """The share of frames whose root does not move."""
    still = [float(np.mean(np.linalg.norm(np.diff(m[:, j.skeleton.root], axis=0), axis=-1) < 1e-9)) for m in j.motions]
    return {"stillness": scoring.spread(still)}

  try:
    take = bundled_path("cmu94") / "94_01_skeleton_3d.csv"
    frozen = tmp_path / "frozen.csv"
    frozen.write_text("\n".join([take.read_text().splitlines()[0]] * 300) + "\n")
    out = tmp_path / "m.json"
    refs = [str(bundled_path("cmu94") / f"94_0{k}_skeleton_3d.csv") for k in (3, 4)]
    assert cli.main(["metrics", str(frozen), str(take), "--data", *refs, "-o", str(out)]) == 0
    assert json.loads(out.read_text())["stillness"] == {"mean": 0.5, "sd": pytest.approx(np.sqrt(0.5))}
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines if line.startswith(("root_travel", "stillness"))] == [
      "root_travel",
      "stillness",
    ]
    # and chorjax eval's report: a tiny run's sample judged on two takes
    from helpers import tiny_config

    from chorjax.training.driver import train_and_evaluate

    train_and_evaluate(tiny_config("log.tensorboard=false", "train.calibrate=false"), tmp_path / "run")
    ev = ["eval", str(tmp_path / "run"), "--data", *refs, "--frames", "300", "-o", str(tmp_path / "e.json")]
    assert cli.main(ev) == 0
    assert "stillness" in json.loads((tmp_path / "e.json").read_text())
    assert any(line.startswith("stillness") for line in capsys.readouterr().out.splitlines())
  finally:
    scoring.METRICS.pop("stillness")
  text = (Path(__file__).resolve().parents[1] / "docs" / "metrics.md").read_text()
  for m in scoring.METRICS.values():
    printed = ", ".join(f"`{k}`" for k in m.printed) or "-"
    assert f"| {m.name} | {printed} | {m.summary} |" in text, m.name
