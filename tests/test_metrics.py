"""Metrics on constructed cases and real takes; eval, sweep and compare end to end (tiny)."""

import json

import numpy as np
import pytest
import scipy.linalg
from helpers import TINY

from chorjax import cli
from chorjax import metrics as M
from chorjax.data import transforms as tf
from chorjax.data.csv import read_csv
from chorjax.data.dataset import bundled_path
from chorjax.data.skeletons import MPII16

TAKE = read_csv(bundled_path("cmu94") / "94_05_skeleton_3d.csv")
POS = np.asarray(tf.rotate(TAKE.positions, tf.up_axis_matrix("-y")))  # y-up


def test_freeze_ratio_zero_for_a_frozen_sequence_and_one_for_the_data():
  frozen = np.repeat(POS[:1], 500, axis=0)
  speed = M.joint_speed(POS).mean()
  assert M.freeze_ratio(frozen, speed) == 0.0
  assert M.freeze_ratio(POS, speed) == pytest.approx(1.0)
  assert np.all(M.freeze_curve(frozen, speed) == 0) and len(M.freeze_curve(POS, speed, 100)) == len(POS) // 100


def test_bone_cv_zero_for_a_rigid_skeleton():
  pose = POS[0]
  t = np.linspace(0, 3, 200)
  rot = np.stack([np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]]) for a in t])
  rigid = np.einsum("tij,kj->tki", rot, pose) + t[:, None, None] * 10
  assert M.bone_cv(rigid, MPII16)["max"] < 1e-6
  assert M.bone_cv(POS, MPII16)["median"] <= 0.03


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
  assert abs(M.fid_k(feats, feats)["fid_k"]) < 1e-4  # round-off against a covariance trace of ~48


def test_novelty_zero_for_a_copied_window_and_positive_otherwise():
  train = M.windows(POS, 60, 10)
  assert M.novelty(train[3:5], train, MPII16.root) == pytest.approx(0.0, abs=1e-3)
  other = read_csv(bundled_path("cmu94") / "94_10_skeleton_3d.csv").positions
  held = M.windows(np.asarray(tf.rotate(other, tf.up_axis_matrix("-y"))), 60, 30)
  assert M.novelty(held, train, MPII16.root) > 1.0


# ---------------------------------------------------------------- eval, sweep, compare


def test_sweep_eval_compare_end_to_end(tmp_path, monkeypatch, capsys):
  monkeypatch.chdir(tmp_path)
  set_lines = "\n".join(
    f'"{k}" = {v if v.replace(".", "").replace("-", "").isdigit() or v in ("true", "false") else json.dumps(v)}'
    for k, v in (o.split("=", 1) for o in TINY)
  )
  (tmp_path / "base.toml").write_text("")
  sweep = tmp_path / "s.toml"
  sweep.write_text(
    f'name = "t"\nbase = "base.toml"\n[grid]\n"model.head" = ["mdn", "mse"]\n[set]\n{set_lines}\n'
    '"log.tensorboard" = false\n[eval]\ndata = ["cmu94/94_10_skeleton_3d.csv"]\nframes = 240\nnum = 2\n'
  )
  assert cli.main(["sweep", str(sweep)]) == 0
  runs = sorted((tmp_path / "runs" / "t").iterdir())
  assert [r.name for r in runs] == ["t-head=mdn", "t-head=mse"]
  m = json.loads((runs[0] / "eval" / "metrics.json").read_text())
  for key in (
    "heldout_loss",
    "freeze_ratio_first_1000",
    "freeze_ratio_last_1000",
    "bone_cv_median",
    "foot_sliding",
    "fid_k",
    "div_k",
    "real_fid_k",
    "novelty",
    "real_novelty",
  ):
    assert np.isfinite(m[key]), key
  assert m["loss_kind"] == "nll" and json.loads((runs[1] / "eval" / "metrics.json").read_text())["loss_kind"] == "mse"
  capsys.readouterr()
  assert cli.main(["sweep", str(sweep)]) == 0  # finished points are skipped
  assert capsys.readouterr().out.count("finished, skipped") == 2
  report = tmp_path / "report.md"
  assert cli.main(["compare", *map(str, runs), "-o", str(report)]) == 0
  text = report.read_text()
  assert "| t-head=mdn | lnlstm | mdn |" in text and "## Who wins" in text and "not comparable" in text
  assert (tmp_path / "report_loss.png").exists() and (tmp_path / "report_freeze.png").exists()
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
  assert m["fid_k"] >= 0 and m["real_fid_k"] >= 0 and m["div_k"] > 0 and np.isfinite(m["heldout_loss"])
  assert cli.main(["eval", str(runs[0]), "--data", "nope.csv", "-o", str(tmp_path / "m2.json")]) == 2
  assert cli.main(["compare", str(tmp_path), "-o", str(tmp_path / "r2.md")]) == 2
