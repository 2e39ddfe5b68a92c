"""Training: config errors and overrides, learning, one compile, NaN stop, TensorBoard, checkpoints,
locking, and kill -9 + resume == uninterrupted (bit for bit)."""

import dataclasses
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import TINY, read_events, tiny_config

from chorjax import checkpoint as ckpt
from chorjax import cli
from chorjax.config import load_config, to_toml
from chorjax.data.csv import read_csv
from chorjax.data.dataset import WindowSampler, load_dataset
from chorjax.errors import UserError
from chorjax.families.recurrent.steps import create_train_state, eval_step, parted_train_step, train_step
from chorjax.run import load_run
from chorjax.training.driver import train_and_evaluate, workdir_lock
from chorjax.training.loop import due

ROOT = Path(__file__).resolve().parents[1]


def write_config(path: Path, *overrides) -> Path:
  path.write_text(to_toml(tiny_config(*overrides)))
  return path


# ---------------------------------------------------------------- config files


@pytest.mark.parametrize(
  "body, fragment",
  [
    ("[model]\ncel = 'gru'\n", ":2: unknown key 'model.cel'; did you mean 'model.cell'?"),
    ("[model]\n\ncell = 'grux'\n", ":3: key 'model.cell': 'grux' is not one of"),
    ("[optim]\nlr = 'fast'\n", ":2: key 'optim.lr': expected float, got str"),
    ("[train]\nbatch_size = 2.5\n", "key 'train.batch_size': expected int"),
    ("[modle]\ncell = 'gru'\n", "unknown section 'modle'; did you mean 'model'?"),
    ("[train]\nnum_steps = -3\n", "below the minimum"),
    ("[model]\nmdn_radius = 1.5\n", "key 'model.mdn_radius': 1.5 is above the maximum 1.0"),
    ("[model\n", "invalid TOML"),
  ],
)
def test_config_errors_name_file_line_and_key(tmp_path, capsys, body, fragment):
  path = tmp_path / "bad.toml"
  path.write_text(body)
  with pytest.raises(UserError) as e:
    load_config(path)
  assert str(e.value).startswith(str(path)) and fragment in str(e.value)
  assert cli.main(["config", "show", str(path)]) == 2
  err = capsys.readouterr().err
  assert err.count("\n") == 1 and fragment in err


def test_shipped_configs_load_and_overrides_apply(capsys):
  for name in ("quickstart", "notebook", "chor_rnn"):
    cfg = load_config(ROOT / "configs" / f"{name}.toml")
    assert cfg.name == name
  nb = load_config(ROOT / "configs" / "notebook.toml")
  assert (nb.model.cell, nb.model.head, nb.model.num_layers, nb.model.hidden_size) == ("lstm", "mse", 3, 256)
  assert (nb.train.batch_size, nb.data.seq_length, nb.optim.lr, nb.optim.clip_norm) == (50, 100, 1e-3, 10.0)
  assert cli.main(["config", "show", str(ROOT / "configs" / "quickstart.toml"), "model.cell=gru", "optim.lr=3e-4"]) == 0
  out = capsys.readouterr().out
  assert 'cell = "gru"' in out and "lr = 0.0003" in out
  assert load_config(None, ["model.cell=gru"]).model.cell == "gru"


def test_a_config_stands_on_a_base_and_states_only_what_differs(tmp_path, capsys):
  """``base = "FILE"`` (relative to the config): the base's keys, then the config's own; its name is its own.
  configs/library.toml is configs/quickstart.toml and its library keys; ``config show`` prints the resolved whole;
  a missing base, a base that leads back to itself, or a bad key in the base is one line naming the file."""
  quick, library = (load_config(ROOT / "configs" / f"{n}.toml") for n in ("quickstart", "library"))
  library_keys = {"condition_every_frame": True, "mdn_basis": "pca", "mdn_radius": 0.4}
  assert library.name == "library" and library.model == dataclasses.replace(quick.model, **library_keys)
  assert library.sample == quick.sample and library.train.feedback == "auto"
  assert (library.data.dataset, library.data.loop, library.train.epochs) == ("bandai-motion", 3.0, 64.0)
  assert library.optim == quick.optim
  assert cli.main(["config", "show", str(ROOT / "configs" / "library.toml")]) == 0
  shown = capsys.readouterr().out
  assert "base" not in shown and 'name = "library"' in shown and "hidden_size = 192" in shown
  (tmp_path / "deep").mkdir()
  (tmp_path / "deep" / "mine.toml").write_text('base = "../parent.toml"\n[optim]\nlr = 1e-4\n')
  (tmp_path / "parent.toml").write_text('name = "parent"\n[model]\ncell = "gru"\n[optim]\nlr = 5e-3\n')
  mine = load_config(tmp_path / "deep" / "mine.toml")
  assert (mine.name, mine.model.cell, mine.optim.lr) == ("mine", "gru", 1e-4)
  (tmp_path / "parent.toml").write_text('base = "deep/mine.toml"\n')
  (tmp_path / "lost.toml").write_text('\nbase = "nowhere.toml"\n')
  (tmp_path / "badbase.toml").write_text('base = "bad.toml"\n')
  (tmp_path / "bad.toml").write_text("[model]\ncel = 'gru'\n")
  for path, said in (
    (tmp_path / "deep" / "mine.toml", "leads back to itself"),
    (tmp_path / "lost.toml", "lost.toml:2: base 'nowhere.toml': no such file"),
    (tmp_path / "badbase.toml", "bad.toml:2: unknown key 'model.cel'"),
  ):
    assert cli.main(["config", "show", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and said in err, err


# ---------------------------------------------------------------- the step


@pytest.fixture(scope="module")
def tiny_setup():
  cfg = tiny_config("optim.lr=3e-3")
  ds = load_dataset(cfg.data)
  return cfg, ds


@pytest.mark.parametrize("head", ["mse", "mdn"])
def test_a_few_steps_lower_the_loss_and_the_step_compiles_once(tiny_setup, head):
  cfg, ds = tiny_setup
  cfg = load_config(None, [*TINY, "optim.lr=3e-3", f"model.head={head}"])
  state, spec = create_train_state(cfg, 48, ds.num_motions)
  sampler = WindowSampler(ds.train, cfg.data.seq_length, 16, seed=0)
  held = sampler.batch(10_000)
  before = float(eval_step(state["params"], held, spec.graphdef))
  key = jax.random.key(0)
  traces = train_step._cache_size()
  for s in range(40):
    state, metrics = train_step(state, sampler.batch(s), key, spec)
  after = float(eval_step(state["params"], held, spec.graphdef))
  assert after < 0.9 * before if head == "mse" else after < before - 5.0
  assert train_step._cache_size() == traces + 1  # one compile for this spec: no silent recompiles
  assert float(metrics["lr"]) == pytest.approx(3e-3) and 0 < float(metrics["grad_norm"]) < 1e4
  norm = lambda tree: np.sqrt(sum(float(np.sum(np.square(x))) for x in jax.tree.leaves(tree)))
  assert float(metrics["param_norm"]) == pytest.approx(norm(state["params"]), rel=1e-5)
  assert 0 < float(metrics["update_norm"]) < 0.1 * float(metrics["param_norm"])
  assert int(state["step"]) == 40


@pytest.mark.parametrize("head", ["mse", "mdn"])
def test_a_batch_in_shares_side_by_side_makes_the_update_of_the_whole_batch(tiny_setup, head):
  """``train.batch_parts``: without noise or dropout, the mean of the shares' gradients is the whole batch's (to
  float rounding), so one step of each lands on the same parameters and metrics; ``min_`` metrics take the
  least of the shares'. The shares in threads and in one program (as vectorized training runs them) land on
  the same parameters (the same bits where programs compile as a user's do: the suite's quick compiling fuses
  them otherwise)."""
  _, ds = tiny_setup
  cfg = load_config(None, [*TINY, f"model.head={head}", "model.dropout=0", "train.input_noise=0"])
  state, spec = create_train_state(cfg, 48, ds.num_motions)
  batch = WindowSampler(ds.train, cfg.data.seq_length, 8, seed=0).batch(3)
  copy = jax.tree.map(jnp.array, state)
  whole, m_whole = train_step(state, batch, jax.random.key(0), spec)
  for parts in (2, 4):
    spec_p = dataclasses.replace(spec, parts=parts)
    parted, m_parted = parted_train_step(jax.tree.map(jnp.array, copy), batch, jax.random.key(0), spec_p)
    assert int(parted["step"]) == 1
    one = train_step(jax.tree.map(jnp.array, copy), batch, jax.random.key(0), spec_p)[0]  # the shares in one program
    for a, b in zip(jax.tree.leaves(one), jax.tree.leaves(parted), strict=True):
      np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-7)  # the bits, but for the suite's quick compiling
    for a, b in zip(jax.tree.leaves(parted["params"]), jax.tree.leaves(whole["params"]), strict=True):
      np.testing.assert_allclose(a, b, rtol=2e-4, atol=2e-6)
    for k in m_whole:
      assert float(m_parted[k]) == pytest.approx(float(m_whole[k]), rel=2e-4), k
  assert ("min_scale" in m_whole) == (head == "mdn")
  for refused in (["train.batch_size=9"], ["parallel.data_parallel=true"], ["model.family=gan"]):
    assert cli_error(["train.batch_parts=2", *refused]) == "key 'train.batch_parts'", refused


def cli_error(overrides):
  """The start of the one-line error loading the default config with ``overrides`` gives."""
  with pytest.raises(UserError) as e:
    load_config(None, [*TINY, *overrides])
  return str(e.value).split(":")[0]


def test_non_finite_loss_stops_the_run_and_keeps_the_last_good_checkpoint(tmp_path, capsys):
  cfg = write_config(
    tmp_path / "nan.toml", "optim.lr=1e30", "optim.clip_norm=0.0", "train.num_steps=40", "train.checkpoint_every=1"
  )
  assert cli.main(["train", str(cfg), "--workdir", str(tmp_path / "w"), "log.tensorboard=false"]) == 2
  err = capsys.readouterr().err
  assert "non-finite loss" in err and "at step" in err and err.count("\n") == 1
  m = ckpt.create_manager(tmp_path / "w", read_only=True)
  steps = m.all_steps()
  m.close()
  bad_step = int(err.split("at step ")[1].split(";")[0])
  assert steps and max(steps) < bad_step  # nothing was saved at or after the bad step


# ---------------------------------------------------------------- the run directory


def test_run_directory_holds_config_metrics_events_checkpoints_and_sample(tmp_path):
  cfg = tiny_config(
    "train.num_steps=6", "train.checkpoint_every=3", "train.eval_every=3", "train.log_every=2", "train.figure_every=3"
  )
  summary = train_and_evaluate(cfg, tmp_path)
  assert json.loads((tmp_path / "config.json").read_text())["model"] == cfg.to_dict()["model"]
  rows = [json.loads(l) for l in (tmp_path / "metrics.jsonl").read_text().splitlines()]
  assert [r["step"] for r in rows] == [2, 3, 4, 6] and all("train_loss" in r for r in rows)
  assert "val_loss" in rows[1] and "val_loss" in rows[-1]
  scalars, images = read_events(next(tmp_path.glob("events.out.tfevents.*")))
  assert [s for s, _ in images["sample/end_joints"]] == [3, 6]
  assert images["sample/end_joints"][0][1][:4] == b"\x89PNG"  # a generated sample beside a real one
  assert [s for s, _ in scalars["train/loss"]] == [2, 3, 4, 6]
  assert scalars["val/val_loss"][-1][1] == pytest.approx(rows[-1]["val_loss"])
  run = load_run(tmp_path, "latest")
  assert run.step == 6 and run.config == cfg and run.num_motions == 10
  assert run.features.mean.shape == (48,) and run.val_loss == pytest.approx(rows[-1]["val_loss"])
  assert len(run.train_takes) == 9 and run.val_takes == ("94_10_skeleton_3d",)
  manager = ckpt.open_run(tmp_path)
  meta = ckpt.step_meta(manager, 6)  # resuming reads the data sampler's position from it
  manager.close()
  assert meta["sampler"]["position"] == 6 and meta["rng"] == {"seed": 0, "fold_in": "step"}
  assert Path(summary["samples"]["csv"]).exists() and Path(summary["samples"]["html"]).exists()
  # resume: continue the same run to 8 steps
  cfg2 = tiny_config("train.num_steps=8", "train.checkpoint_every=3", "train.eval_every=3", "train.log_every=2")
  assert train_and_evaluate(cfg2, tmp_path)["start_step"] == 6


def test_periodic_actions_follow_one_due_rule():
  assert [s for s in range(1, 11) if due(s, 4, 10)] == [4, 8, 10]  # every 4 steps and at the last
  assert [s for s in range(1, 11) if due(s, 0, 10)] == [10]  # 0: only at the last


@pytest.mark.parametrize("older", [False, True])
def test_a_reopened_manager_keeps_the_best_step(tmp_path, older):
  """The best step by validation loss outlives a reopening (a resumed run) and the saves after it; ``older``:
  steps written before orbax stored their metrics (chorjax before 2026-11-27) get them from their meta."""
  state = lambda s: {"params": {"w": np.full(3, s, np.float32)}, "opt_state": {"m": np.zeros(1)}, "step": np.int32(s)}
  manager = ckpt.create_manager(tmp_path, keep=1)
  for step, val in ((10, 3.0), (20, 2.0), (30, 2.5)):
    ckpt.save(manager, step, state(step), {"step": step}, val)
  manager.close()
  assert manager.all_steps() == [20, 30]
  if older:
    for metrics in (tmp_path / "checkpoints").glob("*/metrics"):
      shutil.rmtree(metrics)
  manager = ckpt.create_manager(tmp_path, keep=1)
  for step, val in ((40, 2.7), (50, None)):
    ckpt.save(manager, step, state(step), {"step": step}, val)
  assert manager.all_steps() == [20, 50] and ckpt.best_step(manager) == 20
  manager.close()


def test_params_are_their_own_checkpoint_item_and_a_run_written_before_that_still_samples(tmp_path, capsys):
  cfg = tiny_config("train.num_steps=2", "log.tensorboard=false")
  train_and_evaluate(cfg, tmp_path / "new")
  assert sorted(p.name for p in (tmp_path / "new" / "checkpoints" / "2").iterdir() if p.is_dir()) == [
    "meta",
    "metrics",  # orbax's: the step's validation loss, which a resumed run's manager reads back
    "params",
    "train",
  ]
  # tests/fixtures/legacy_run: written by chorjax 539c1f4 (one 'state' item holding params and optimizer)
  legacy = shutil.copytree(ROOT / "tests" / "fixtures" / "legacy_run", tmp_path / "legacy")
  assert (legacy / "checkpoints" / "6" / "state").is_dir() and not (legacy / "checkpoints" / "6" / "params").exists()
  run = load_run(legacy)
  assert (run.step, run.config.model.cell, run.num_motions) == (6, "lstm", 10)
  out = tmp_path / "s.csv"
  assert cli.main(["sample", str(legacy), "-o", str(out), "--frames", "30", "--seed", "3"]) == 0
  then = read_csv(legacy / "sample_seed3_30frames.csv").positions  # what chorjax 539c1f4 sampled
  np.testing.assert_allclose(read_csv(out).positions, then, rtol=1e-5, atol=1e-3)
  # and training continues it (state restored from the old item, new checkpoints in the new layout)
  more = load_config(legacy / "tiny.toml", ["train.num_steps=8", "sample.frames=1"])
  assert train_and_evaluate(more, legacy)["start_step"] == 6
  assert (legacy / "checkpoints" / "8" / "params").is_dir()


def test_best_checkpoint_is_kept_beside_the_latest(tmp_path):
  m = ckpt.create_manager(tmp_path, keep=1)
  state = {"params": {"x": np.zeros(3, np.float32)}, "opt_state": (), "step": np.zeros((), np.int32)}
  for step, val in [(1, 0.5), (2, 0.1), (3, 0.9), (4, 0.7)]:
    ckpt.save(m, step, state, {"step": step}, val)
  m.wait_until_finished()
  assert sorted(m.all_steps()) == [2, 4] and ckpt.best_step(m) == 2
  m.close()


def test_a_workdir_in_use_or_with_another_config_is_refused(tmp_path, capsys):
  cfg = write_config(tmp_path / "c.toml")
  w = tmp_path / "w"
  with workdir_lock(w):
    assert cli.main(["train", str(cfg), "--workdir", str(w)]) == 2
  assert "in use by another" in capsys.readouterr().err
  assert cli.main(["train", str(cfg), "--workdir", str(w), "log.tensorboard=false"]) == 0
  assert cli.main(["train", str(cfg), "--workdir", str(w), "model.hidden_size=8"]) == 2
  assert "different config" in capsys.readouterr().err
  # --force continues; the old config is kept beside the new one, and a changed shape is a clean error
  assert cli.main(["train", str(cfg), "--workdir", str(w), "optim.lr=5e-4", "--force"]) == 0
  assert len(list(w.glob("config.*.json"))) == 1
  # a --force that fails (the checkpoint cannot hold the changed model) leaves the workdir as it was
  before = {p.name: p.read_bytes() for p in w.glob("config*.json")}
  capsys.readouterr()
  assert cli.main(["train", str(cfg), "--workdir", str(w), "model.hidden_size=8", "--force"]) == 2
  assert capsys.readouterr().err.count("\n") == 1
  assert {p.name: p.read_bytes() for p in w.glob("config*.json")} == before
  assert cli.main(["train", str(cfg), "--workdir", str(w), "model.hidden_size=8"]) == 2  # still refused


def test_missing_checkpoint_is_a_clean_error(tmp_path, capsys):
  assert cli.main(["sample", str(tmp_path), "-o", str(tmp_path / "s.csv")]) == 2
  assert "no checkpoints" in capsys.readouterr().err
  assert not (tmp_path / "s.csv").exists()


@pytest.mark.slow
def test_resume_after_sigkill_is_bit_identical(tmp_path):
  cfg = write_config(
    tmp_path / "c.toml", "train.num_steps=200", "train.checkpoint_every=10", "log.tensorboard=false", "sample.frames=1"
  )
  cmd = [sys.executable, "-m", "chorjax.cli", "train", str(cfg), "--workdir"]
  env = {**os.environ, "PYTHONUNBUFFERED": "1"}
  killed = tmp_path / "killed"
  proc = subprocess.Popen(cmd + [str(killed)], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
  deadline = time.time() + 120
  while not (killed / "checkpoints" / "30").is_dir():
    assert proc.poll() is None and time.time() < deadline, "training ended before it could be killed"
    time.sleep(0.005)
  proc.send_signal(signal.SIGKILL)
  proc.wait()
  assert not (killed / "checkpoints" / "200").exists(), "the run finished before the kill"
  assert subprocess.run(cmd + [str(killed)], env=env, capture_output=True).returncode == 0
  straight = tmp_path / "straight"
  assert subprocess.run(cmd + [str(straight)], env=env, capture_output=True).returncode == 0

  def final_params(w):
    return load_run(w, 200).params

  a, b = final_params(killed), final_params(straight)
  for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
    np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def test_sigint_and_sigterm_save_a_checkpoint_and_resume_exactly(tmp_path, monkeypatch, capsys):
  cfg = write_config(
    tmp_path / "c.toml",
    "train.num_steps=200",
    "train.checkpoint_every=1000",
    "log.tensorboard=false",
    "sample.frames=1",
  )
  run, straight = tmp_path / "run", tmp_path / "straight"
  import chorjax.training.driver as train_mod

  # Ctrl-C (in this process) once step 5 is logged: the step finishes, a checkpoint is saved, exit 130
  log_call = train_mod.MetricsLog.__call__

  def ctrl_c_at_5(self, step, *rest):
    log_call(self, step, *rest)
    if step == 5:
      os.kill(os.getpid(), signal.SIGINT)

  monkeypatch.setattr(train_mod.MetricsLog, "__call__", ctrl_c_at_5)
  assert cli.main(["train", str(cfg), "--workdir", str(run)]) == 130
  err = capsys.readouterr().err
  assert err.count("\n") == 1 and "SIGINT at step" in err and "checkpoint saved" in err
  first = sorted(int(p.name) for p in (run / "checkpoints").iterdir() if p.name.isdigit())
  assert len(first) == 1 and 5 <= first[0] < 200 and not (run / "samples").exists()
  monkeypatch.setattr(train_mod.MetricsLog, "__call__", log_call)
  # SIGTERM (a cluster's preemption) to a resumed run in its own process: exit 143, one line
  cmd = [sys.executable, "-m", "chorjax.cli", "train", str(cfg), "--workdir", str(run)]
  proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
  rows = lambda: len((run / "metrics.jsonl").read_text().splitlines())
  deadline = time.time() + 120
  while rows() <= first[0] + 2:
    assert proc.poll() is None and time.time() < deadline, "training ended before it could be stopped"
    time.sleep(0.01)
  proc.send_signal(signal.SIGTERM)
  _, err = proc.communicate(timeout=120)
  assert proc.returncode == 143 and err.count("\n") == 1 and "SIGTERM at step" in err, err
  second = max(int(p.name) for p in (run / "checkpoints").iterdir() if p.name.isdigit())
  assert first[0] < second < 200
  # resumed to the end, the run equals one never interrupted, bit for bit
  assert cli.main(["train", str(cfg), "--workdir", str(run)]) == 0
  assert cli.main(["train", str(cfg), "--workdir", str(straight)]) == 0
  for x, y in zip(jax.tree.leaves(load_run(run, 200).params), jax.tree.leaves(load_run(straight, 200).params)):
    np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def train_tiny_and_check_it_learns(workdir, *overrides) -> dict:
  """Trains a tiny model for 30 steps; asserts the loss fell and the end sample is finite."""
  cfg = tiny_config("train.num_steps=30", "optim.lr=3e-3", "log.tensorboard=false", "train.log_every=5", *overrides)
  summary = train_and_evaluate(cfg, workdir)
  losses = summary["train_losses"]
  assert np.mean([losses[s] for s in range(26, 31)]) < np.mean([losses[s] for s in range(1, 6)]) - 1.0
  assert np.isfinite(read_csv(summary["samples"]["csv"]).positions).all()
  return summary


@pytest.mark.parametrize("representation", ["canonical", "directions"])
def test_root_motion_representations_train_and_sample(tmp_path, representation):
  summary = train_tiny_and_check_it_learns(tmp_path, f"data.representation={representation!r}", "sample.frames=40")
  sample = read_csv(summary["samples"]["csv"]).positions
  assert sample.shape == (40, 16, 3)
  run = load_run(tmp_path)
  assert run.features.dim == {"canonical": 99, "directions": 51}[representation] == run.features.mean.shape[0]
  if representation == "directions":  # bones at the training takes' mean lengths: no stretching
    from chorjax.data.motion import bone_length_cv

    assert bone_length_cv(sample, run.features.skeleton).max() < 1e-4


# ---------------------------------------------------------------- feeding the model's own outputs back


def _feedback(**kw):
  from chorjax.families.recurrent.steps import Feedback

  base = {
    "mode": "auto",
    "ground_truth_frames": 2,
    "condition_frames": 3,
    "max_fraction": 0.5,
    "warmup": 0,
    "ramp": 0,
    "draw": "mean",
    "pi_temperature": 1.0,
    "sigma_temperature": 1.0,
  }
  return Feedback(**{**base, **kw})


def test_feedback_masks_follow_the_mode_and_the_schedule():
  from chorjax.families.recurrent.steps import feedback_mask

  key, step = jax.random.key(0), jnp.asarray(10)
  auto = np.asarray(feedback_mask(_feedback(), key, step, 4, 12))
  assert auto[0].tolist() == [False, False, True, True, True, False, False, True, True, True, False, False]
  assert (auto == auto[0]).all()  # the same cycle in every sequence once the schedule is full
  sched = np.asarray(feedback_mask(_feedback(mode="scheduled"), key, step, 64, 100))
  assert not sched[:, 0].any() and abs(sched[:, 1:].mean() - 0.5) < 0.03
  assert not np.asarray(feedback_mask(_feedback(mode="scheduled", warmup=11), key, step, 64, 100)).any()
  half = np.asarray(feedback_mask(_feedback(mode="scheduled", warmup=1, ramp=20, max_fraction=1.0), key, step, 64, 100))
  assert abs(half[:, 1:].mean() - 0.5) < 0.03  # 10 of 20 ramp steps done


def test_feedback_replaces_inputs_with_own_outputs_and_is_teacher_forcing_when_off(tiny_setup):
  from chorjax.families.recurrent.steps import StepSpec, _feedback_loss_fn, _loss_fn

  cfg, ds = tiny_setup
  state, spec = create_train_state(cfg, 48, ds.num_motions)
  batch = WindowSampler(ds.train, cfg.data.seq_length, 4, seed=0).batch(0)
  key, step = jax.random.key(1), jnp.asarray(5)
  teacher = float(_loss_fn(state["params"], batch, key, spec)[0])
  off = StepSpec(spec.graphdef, spec.tx, spec.schedule, 0.0, 0.0, _feedback(mode="scheduled", max_fraction=0.0))
  assert float(_feedback_loss_fn(state["params"], batch, key, step, off)[0]) == pytest.approx(teacher, rel=1e-5)
  every = StepSpec(spec.graphdef, spec.tx, spec.schedule, 0.0, 0.0, _feedback(mode="scheduled", max_fraction=1.0))

  def loss_of_inputs(x):
    return _feedback_loss_fn(state["params"], {**batch, "inputs": x}, key, step, every)[0]

  grad = np.asarray(jax.grad(loss_of_inputs)(jnp.asarray(batch["inputs"])))
  assert np.abs(grad[:, 0]).sum() > 0 and not grad[:, 1:].any()  # only frame 0 is real; own frames carry no gradient
  assert float(loss_of_inputs(jnp.asarray(batch["inputs"]))) != pytest.approx(teacher, rel=1e-3)


def test_feedback_drops_the_units_the_whole_window_would_and_is_teacher_forcing_when_off(tiny_setup):
  """Dropout with feedback: run frame by frame with the window's masks, the cells give the fused window's
  dropped-out loss to the last bit of float32 when nothing is fed back, and another loss without masks."""
  from chorjax.families.recurrent.steps import _feedback_loss_fn, _loss_fn

  _, ds = tiny_setup
  cfg = tiny_config("model.dropout=0.3")
  state, spec = create_train_state(cfg, 48, ds.num_motions)
  assert spec.dropout == 0.3
  batch = WindowSampler(ds.train, cfg.data.seq_length, 4, seed=0).batch(0)
  key, step = jax.random.key(2), jnp.asarray(5)
  dropped = float(_loss_fn(state["params"], batch, key, spec)[0])
  plain = float(_loss_fn(state["params"], batch, key, dataclasses.replace(spec, dropout=0.0))[0])
  assert dropped != pytest.approx(plain, rel=1e-3)  # the masks matter on this batch
  off = dataclasses.replace(spec, feedback=_feedback(mode="scheduled", max_fraction=0.0))
  assert float(_feedback_loss_fn(state["params"], batch, key, step, off)[0]) == pytest.approx(dropped, rel=1e-5)


@pytest.mark.parametrize("feedback", ["auto", "scheduled"])
def test_training_with_feedback_lowers_the_loss_and_samples(tmp_path, feedback):
  dropout = ["model.dropout=0.2"] if feedback == "scheduled" else []  # feedback trains with dropout or without
  overrides = (f"train.feedback={feedback!r}", "sample.frames=30", "train.feedback_ramp=10", *dropout)
  train_tiny_and_check_it_learns(tmp_path, *overrides)
  rows = [json.loads(l) for l in (tmp_path / "metrics.jsonl").read_text().splitlines()]
  assert rows[0]["feedback"] < rows[-1]["feedback"] and rows[-1]["feedback"] > 0.2  # the ramp, logged


def test_the_aclstm_config_loads_and_feeds_its_own_outputs_on_5_of_every_10_frames():
  from chorjax.config import load_config
  from chorjax.families.recurrent.steps import Feedback, feedback_mask

  cfg = load_config(Path(__file__).resolve().parents[1] / "configs" / "aclstm.toml")
  assert (cfg.model.cell, cfg.model.head, cfg.model.num_layers, cfg.model.hidden_size) == ("lstm", "mse", 3, 1024)
  assert cfg.data.seq_length == 100 and cfg.data.representation == "root_relative"
  mask = np.asarray(feedback_mask(Feedback.of(cfg), jax.random.key(0), jnp.asarray(0), 3, 100))
  own = [t for t in range(100) if (t % 10) >= 5]  # frames 5-9, 15-19, ...: the network's own outputs
  assert (mask == np.isin(np.arange(100), own)[None]).all()


def test_a_checkpoint_whose_step_is_no_number_is_one_line(tmp_path):
  """A meta step of 'abc' is damage, named with the file, not a ValueError from int()."""
  import json as _json

  from chorjax.errors import UserError as _UserError

  run = tmp_path / "legacy"
  shutil.copytree(ROOT / "tests" / "fixtures" / "legacy_run", run)
  meta = run / "checkpoints" / "6" / "meta" / "metadata"
  data = _json.loads(meta.read_text())
  data["step"] = "abc"
  meta.write_text(_json.dumps(data))
  with pytest.raises(_UserError, match=r"6/meta/metadata: damaged checkpoint"):
    load_run(run)


def test_epochs_size_the_run_to_the_data_and_patience_ends_it_when_the_loss_stops_falling(tmp_path, capsys):
  """``train.epochs`` sets the step count from the training frames; ``train.patience`` ends training after that
  many validation passes without a lower loss (at learning rate 0 the first pass's loss is never lowered: the
  run ends two passes later), with a checkpoint of that step and the end's sample written as usual."""
  import math

  cfg = tiny_config("train.epochs=0.5", "optim.lr=0", "train.eval_every=1", "train.patience=2", "log.tensorboard=false")
  frames = sum(len(x) for _, x in load_dataset(cfg.data).train)
  steps = math.ceil(0.5 * frames / (cfg.train.batch_size * cfg.data.seq_length))
  summary = train_and_evaluate(cfg, tmp_path / "run")
  out = capsys.readouterr().out
  assert f"train.epochs = 0.5: {steps:,} steps ({frames:,} training frames" in out and steps > 3
  assert summary["final_step"] == 3 and "ended at step 3: 2 validation passes without a lower loss" in out
  assert (ckpt.checkpoint_dir(tmp_path / "run") / "3").is_dir() and summary["samples"]
  assert json.loads((tmp_path / "run" / "config.json").read_text())["train"]["num_steps"] == steps

  no_val = tiny_config("train.patience=2", "train.eval_every=1", "data.val_takes=[]", "log.tensorboard=false")
  with pytest.raises(UserError, match=r"train.patience: needs validation passes"):
    train_and_evaluate(no_val, tmp_path / "none")


def test_the_end_of_training_names_the_checkpoint_sample_and_eval_will_use(tmp_path, capsys):
  """With ``train.keep = "best"`` the last line names the kept step and its validation loss (a run whose best
  was early otherwise samples an earlier step than its log's last loss says, silently), and the end sample
  is drawn from that checkpoint, as ``chorjax sample`` draws."""
  from chorjax.run import load_run

  (tmp_path / "base.toml").write_text("")
  args = [*TINY, "log.tensorboard=false", "train.keep=best", "train.eval_every=1", "train.num_steps=6"]
  args.append("optim.lr=1.0")  # it diverges after a few steps: the best is not the last
  assert cli.main(["train", str(tmp_path / "base.toml"), *args, "sample.seed=4", "--workdir", str(tmp_path / "r")]) == 0
  out = capsys.readouterr().out
  run = load_run(tmp_path / "r")
  assert run.step < 6 and f"; kept: step {run.step} (val loss {run.val_loss:.4g})" in out, out
  again = tmp_path / "again.csv"
  assert cli.main(["sample", str(tmp_path / "r"), "-o", str(again), "--frames", "20", "--seed", "4"]) == 0
  np.testing.assert_allclose(
    read_csv(tmp_path / "r" / "samples" / "sample.csv").positions, read_csv(again).positions, atol=1e-5
  )
