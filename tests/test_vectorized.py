"""Vectorized training: K points of one shape as one program, each an ordinary run directory."""

import json

import numpy as np
import pytest
from helpers import TINY, tiny_config

from chorjax import cli
from chorjax.errors import UserError
from chorjax.run import load_run
from chorjax.sweeps import load_sweep, sweep_groups
from chorjax.training.driver import train_and_evaluate
from chorjax.training.points import NotAligned, check_group
from chorjax.training.vectorized import train_vectorized

BASE = ["train.num_steps=4", "log.tensorboard=false", "train.eval_every=2", "train.checkpoint_every=2"]
POINTS = [
  ("train.seed=0", "optim.lr=1e-3", "train.input_noise=0.0"),
  ("train.seed=1", "optim.lr=3e-3", "train.input_noise=0.1"),
]


def test_points_trained_together_match_points_trained_alone(tmp_path):
  cfgs = [tiny_config(*BASE, *p) for p in POINTS]
  together = train_vectorized(cfgs, [tmp_path / "v0", tmp_path / "v1"])
  for k, cfg in enumerate(cfgs):
    alone = train_and_evaluate(cfg, tmp_path / f"a{k}")
    got, want = together[k]["train_losses"], alone["train_losses"]
    assert got[1] == pytest.approx(want[1], rel=1e-4)  # the first step: same init, batch, keys and noise
    np.testing.assert_allclose([got[s] for s in sorted(got)], [want[s] for s in sorted(want)], rtol=1e-3)
    assert together[k]["final_val_loss"] == pytest.approx(alone["final_val_loss"], rel=1e-3)
    # an ordinary run directory: its own config, metrics, checkpoints and end sample
    run = load_run(tmp_path / f"v{k}")
    assert run.step == 4 and run.config.train.seed == k and run.config.optim.lr == cfg.optim.lr
    rows = [json.loads(l) for l in (tmp_path / f"v{k}" / "metrics.jsonl").read_text().splitlines()]
    assert [r["step"] for r in rows] == [1, 2, 3, 4]
    assert rows[-1]["lr"] == pytest.approx(cfg.optim.lr)  # its own learning rate, logged
    assert (tmp_path / f"v{k}" / "samples" / "sample.csv").exists()
  assert cli.main(["sample", str(tmp_path / "v1"), "--frames", "10", "-o", str(tmp_path / "s1.csv")]) == 0


def test_points_trained_together_in_shares_match_points_trained_alone_in_shares(tmp_path):
  """``train.batch_parts``: a vectorized program computes each point's shares one after another, a lone run in
  threads; each share keeps its own cut of the batch, key, noise and dropout either way."""
  same = [*BASE, "model.dropout=0.3", "train.log_every=1", "sample.frames=1"]
  cfgs = [tiny_config(*same, "train.batch_parts=2", *p) for p in POINTS]
  together = train_vectorized(cfgs, [tmp_path / "v0", tmp_path / "v1"])
  for k, cfg in enumerate(cfgs):
    alone = train_and_evaluate(cfg, tmp_path / f"a{k}")
    whole = train_and_evaluate(tiny_config(*same, *POINTS[k]), tmp_path / f"w{k}")
    got, want, other = (r["train_losses"] for r in (together[k], alone, whole))
    assert got[1] == pytest.approx(want[1], rel=1e-4)
    assert abs(other[1] - want[1]) > 1e-3 * abs(want[1])  # one share's noise and dropout would not do
    np.testing.assert_allclose([got[s] for s in sorted(got)], [want[s] for s in sorted(want)], rtol=1e-3)


def test_train_with_a_list_of_seeds_resumes_exactly(tmp_path, capsys):
  (tmp_path / "base.toml").write_text("")  # the defaults
  args = ["train", str(tmp_path / "base.toml"), *TINY, "log.tensorboard=false", "train.checkpoint_every=2"]
  assert cli.main([*args, "train.seed=[0, 1]", "--workdir", str(tmp_path / "w")]) == 0  # 2 steps
  out = capsys.readouterr().out
  assert "training 2 points as one program: seed=0, seed=1" in out and "trained seed=1: steps 0->2" in out
  same = ["log.tensorboard=false", "train.checkpoint_every=2"]  # a point at step 0 cannot join one at step 2
  pair = [tiny_config(*same, "train.seed=0"), tiny_config(*same, "train.seed=2")]
  with pytest.raises(NotAligned, match=r"different steps \(2, 0\)"):
    train_vectorized(pair, [tmp_path / "w" / "seed=0", tmp_path / "p"])
  more = ["train.num_steps=4", "train.seed=[0, 1]", "--workdir", str(tmp_path / "w")]
  assert cli.main([*args, *more]) == 0  # resumed at step 2, together
  assert "trained seed=0: steps 2->4" in capsys.readouterr().out
  straight = [tiny_config("train.num_steps=4", "log.tensorboard=false", f"train.seed={s}") for s in (0, 1)]
  want = train_vectorized(straight, [tmp_path / "s0", tmp_path / "s1"])  # never interrupted
  for k in (0, 1):
    rows = [json.loads(l) for l in (tmp_path / "w" / f"seed={k}" / "metrics.jsonl").read_text().splitlines()]
    assert [r["train_loss"] for r in rows if r["step"] > 2] == [want[k]["train_losses"][s] for s in (3, 4)]


def test_what_cannot_be_vectorized_is_named(tmp_path):
  with pytest.raises(
    UserError, match=r"cannot vectorize model.hidden_size \(16 vs 32\): it changes the model's shapes"
  ):
    check_group([tiny_config(), tiny_config("model.hidden_size=32")])
  with pytest.raises(UserError, match=r"cannot vectorize data.seq_length"):
    check_group([tiny_config(), tiny_config("data.seq_length=16")])
  assert check_group([tiny_config(), tiny_config("train.seed=3", "sample.frames=5", "name='x'")]) == ["train.seed"]
  sweep = tmp_path / "s.toml"
  sweep.write_text('vectorize = ["model.cell"]\n[grid]\n"train.seed" = [0, 1]\n')
  with pytest.raises(UserError, match=r"s.toml: vectorize: cannot vectorize 'model.cell'"):
    load_sweep(sweep)
  sweep.write_text('vectorize = ["train.seed"]\n[grid]\n"model.head" = ["mdn", "mse"]\n"train.seed" = [0, 1, 2]\n')
  groups = sweep_groups(load_sweep(sweep))
  assert [[n for n, _ in g] for g in groups] == [
    ["s-head=mdn-seed=0", "s-head=mdn-seed=1", "s-head=mdn-seed=2"],
    ["s-head=mse-seed=0", "s-head=mse-seed=1", "s-head=mse-seed=2"],
  ]


def test_points_trained_together_are_calibrated_as_each_would_be_alone(tmp_path, monkeypatch):
  """`train.calibrate` (the quickstart's): every point of a vectorized run chooses its own sampling settings on
  its training takes and draws its end sample with them, as it would trained alone (a 2-setting grid here)."""
  from chorjax.sampling import calibrate

  monkeypatch.setattr(calibrate, "GRID", {**{k: v[:1] for k, v in calibrate.GRID.items()}, "foot_lock": (True, False)})
  overrides = [*BASE, "train.calibrate=true", "data.representation=canonical", "sample.frames=20"]
  cfgs = [tiny_config(*overrides, *p) for p in POINTS]
  train_vectorized(cfgs, [tmp_path / "v0", tmp_path / "v1"])
  for k in range(2):
    saved = json.loads((tmp_path / f"v{k}" / "calibration.json").read_text())
    assert len(saved["table"]) == 2 and set(saved["settings"]) == {*calibrate.GRID, *calibrate.RECORDED}
    assert saved["settings"]["noise_order"] == cfgs[k].sample.noise_order  # the order it was chosen with
    assert saved["settings"]["pace"] == cfgs[k].sample.pace  # and the governor's gain
    assert load_run(tmp_path / f"v{k}").sampling().foot_lock == saved["settings"]["foot_lock"]
    assert (tmp_path / f"v{k}" / "samples" / "sample.csv").exists()


def test_points_trained_together_keep_their_best_checkpoint_where_it_happens(tmp_path):
  """train.keep = "best" (the quickstart's): each point of a vectorized run saves its own best step at the
  evaluation where it happens, as trained alone; it was saved only at checkpoint_every, so the dancers
  benchmark's vectorized sweeps judged the best of every 500th step (lr 0.3: the held-out loss rises)."""
  opts = [*BASE, "train.num_steps=40", "train.eval_every=10", "train.checkpoint_every=40", "optim.lr=0.3"]
  cfgs = [tiny_config(*opts, "train.keep=best", f"train.seed={s}") for s in (0, 1)]
  train_vectorized(cfgs, [tmp_path / "v0", tmp_path / "v1"])
  for k in (0, 1):
    rows = [json.loads(l) for l in (tmp_path / f"v{k}" / "metrics.jsonl").read_text().splitlines()]
    curve = {r["step"]: r["val_loss"] for r in rows if "val_loss" in r}
    best = min(curve, key=curve.__getitem__)
    assert load_run(tmp_path / f"v{k}").step == best < 40 and load_run(tmp_path / f"v{k}", "latest").step == 40
