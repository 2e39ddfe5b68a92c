"""In-betweening (model.family = "inbetween"): the local space, the transition batches of real cmu94 windows,
the untrained model is linear interpolation, training lowers the loss, the command's boundary frames and
chaining, seeds that differ, the metrics, and bad input refused."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import nnx
from helpers import tiny_config

from benchmarks import lafan1
from chorjax import cli
from chorjax.data.dataset import bundled_path, load_dataset
from chorjax.data.npz import read_npz
from chorjax.evaluation.metrics import foot_skate, l2p, npss, position_error
from chorjax.families.inbetween import inbetweening as ib
from chorjax.families.inbetween.cvae_model import transition_model
from chorjax.families.inbetween.lstm_model import noise_strength, rollout, tta_embedding
from chorjax.run import load_run
from chorjax.training.driver import train_and_evaluate

IB = [
  "model.family=inbetween",
  "model.cell=lstm",
  "model.num_layers=1",
  "model.hidden_size=32",
  "inbetween.encoder_sizes=[32]",
  "inbetween.decoder_sizes=[32]",
  "inbetween.context=4",
  "inbetween.min_frames=2",
  "inbetween.max_frames=8",
  "train.batch_size=8",
  "optim.lr=3e-3",
]
TAKE = bundled_path("cmu94") / "94_10_skeleton_3d.csv"


@pytest.fixture(scope="module")
def setup():
  cfg = tiny_config(*IB)
  ds = load_dataset(cfg.data)
  return cfg, ds, ib.Space.of(ds.features)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
  """A tiny in-betweening run trained 60 steps (with its end sample)."""
  workdir = tmp_path_factory.mktemp("ib") / "run"
  cfg = tiny_config(*IB, "train.num_steps=60", "train.eval_every=30", "sample.frames=30")
  summary = train_and_evaluate(cfg, workdir)
  return workdir, summary


def test_local_space_puts_the_anchor_frame_at_the_origin_facing_z(setup):
  _cfg, ds, space = setup
  take = ib.held_out_takes(ds)[0]
  win = take[100:120]
  anchor = space.anchor(win[9])
  local = space.to_local(win, anchor).reshape(20, -1, 3)
  root = ds.features.skeleton.root
  assert np.allclose(local[9, root, [0, 2]], 0.0, atol=1e-5)
  across = local[9, space.left] - local[9, space.right]
  assert abs(across[2]) < 1e-4 and across[0] > 0  # hips along x: facing +z
  assert np.allclose(space.from_local(local.reshape(20, -1), anchor), win, atol=1e-4)
  legs = np.linalg.norm(np.diff(local, axis=0), axis=-1).mean()
  assert 0.001 < legs < 0.2  # leg lengths per frame: a dancer moves a few hundredths of a leg a frame


def test_training_batches_are_real_windows_with_lengths_in_range_and_repeatable(setup):
  cfg, ds, space = setup
  sampler = ib.TransitionSampler(ib.training_takes(ds, ()), space, cfg.inbetween, 8, seed=3)
  a, b = sampler.batch(5), sampler.batch(5)
  assert a["window"].shape == (8, 4 + 8 + 1, 48) and np.array_equal(a["window"], b["window"])
  assert not np.array_equal(a["window"], sampler.batch(6)["window"])
  assert a["length"].min() >= 2 and a["length"].max() <= 8
  root = ds.features.skeleton.root
  assert np.allclose(a["window"][:, 3].reshape(8, -1, 3)[:, root, [0, 2]], 0.0, atol=1e-5)


def test_an_untrained_model_is_linear_interpolation_and_its_embeddings(setup):
  cfg, ds, space = setup
  graphdef, params = nnx.split(transition_model(cfg, ds.features), nnx.Param)
  sampler = ib.TransitionSampler(ib.training_takes(ds, ()), space, cfg.inbetween, 4, seed=0)
  win = sampler.batch(0)["window"]
  out = ib.model_transitions(graphdef, params, cfg.inbetween, win[:, :4], win[:, 10], 6, jax.random.key(0))
  assert np.allclose(out, lafan1.linear(win[:, :4], win[:, 10], 6), atol=1e-6)  # the decoder starts at zero
  emb = tta_embedding(jnp.array([1, 30]), 32)
  assert emb.shape == (2, 32) and not np.allclose(emb[0], emb[1])
  assert np.allclose(noise_strength(jnp.array([3.0, 5.0, 17.5, 30.0, 40.0])), [0, 0, 0.5, 1, 1])


def test_a_train_step_lowers_the_loss_on_a_fixed_batch(setup):
  cfg, ds, space = setup
  state, spec = ib.create_inbetween_state(cfg, ds.features)
  sampler = ib.TransitionSampler(ib.training_takes(ds, ()), space, cfg.inbetween, 8, seed=0)
  batch = {k: jnp.asarray(v) for k, v in sampler.batch(0).items()}
  key = jax.random.key(0)
  first, _ = ib.transition_loss(state["params"], batch, key, spec)
  for _ in range(40):
    state, _metrics = ib.inbetween_train_step(state, batch, key, spec)
  last, aux = ib.transition_loss(state["params"], batch, key, spec)
  assert float(last) < 0.8 * float(first) and set(aux) == {"pose_l1", "step_l1"}


def test_rollout_gives_each_row_its_own_length(setup):
  cfg, ds, _ = setup
  model = transition_model(cfg, ds.features)
  ctx = jnp.asarray(np.random.default_rng(0).normal(size=(2, 4, 48)), jnp.float32)
  target, z = ctx[:, -1] + 1.0, jnp.zeros((2, 32))
  out = np.asarray(rollout(model, ctx, target, jnp.array([5, 3]), 7, z))
  assert out.shape == (2, 7, 48)
  assert np.allclose(out[0, :5], lafan1.linear(np.asarray(ctx[:1]), np.asarray(target[:1]), 5)[0], atol=1e-6)
  assert np.allclose(out[1, :3], lafan1.linear(np.asarray(ctx[1:]), np.asarray(target[1:]), 3)[0], atol=1e-6)
  assert np.allclose(out[1, 3:], target[1], atol=1e-6)  # past its target a row stays there


def test_trained_run_writes_transitions_with_context_and_target_unchanged(trained, tmp_path, capsys):
  workdir, summary = trained
  assert summary["final_val_loss"] > 0 and (workdir / "samples" / "player.html").exists()
  rows = [json.loads(l) for l in (workdir / "metrics.jsonl").read_text().splitlines()]
  assert {"pose_l1", "step_l1", "val_loss"} <= set().union(*rows)
  out = tmp_path / "t.npz"
  argv = ["inbetween", str(workdir), "--from", f"{TAKE}:100:6", "--to", f"{TAKE}:140", "--frames", "12", "-o", str(out)]
  assert cli.main([*argv, "--num", "2", "--seed", "1"]) == 0
  pieces = read_npz(out)
  run = load_run(workdir)
  from chorjax.sample import read_phrase

  real = read_phrase(str(TAKE), run.features, run.config.data)
  assert len(pieces) == 2 and pieces[0].num_frames == 6 + 12 + 1
  for p in pieces:
    assert np.array_equal(p.positions[:6], real[100:106]) and np.array_equal(p.positions[-1], real[140])
  step = lambda x: np.linalg.norm(np.diff(x, axis=0), axis=-1).mean(-1)
  into_target = step(pieces[0].positions[-2:])[0]
  assert into_target <= np.percentile(step(real), 99)  # no larger than the dancer's own frame-to-frame motion


def test_seeds_write_different_transitions_and_key_poses_chain(trained, tmp_path):
  workdir, _ = trained
  run = load_run(workdir)
  from chorjax.sample import read_phrase

  real = read_phrase(str(TAKE), run.features, run.config.data)
  f, cfg = run.features, run.config.inbetween
  write = lambda seed, targets, frames: ib.write_transitions(
    run.graphdef, run.params, f, cfg, real[0:6], targets, frames, jax.random.key(seed)
  )[0]
  a, b = write(0, [real[40]], [20]), write(1, [real[40]], [20])
  assert not np.allclose(a[6:26], b[6:26])  # z_target: another seed, another transition
  chained = write(0, [real[40], real[60], real[90]], [20, 8, 5])
  assert chained.shape[0] == 6 + 21 + 9 + 6
  assert np.array_equal(chained[26], real[40]) and np.array_equal(chained[35], real[60])
  assert np.array_equal(chained[-1], real[90])


def test_metrics_on_known_cases():
  rng = np.random.default_rng(0)
  real = rng.normal(size=(3, 20, 6)).astype(np.float32)
  assert l2p(real, real, np.ones(6)) == 0 and position_error(real, real) == 0 and npss(real, real) < 1e-12
  shifted = real + np.array([3.0, 4.0, 0.0] * 2, np.float32)
  assert np.isclose(position_error(shifted, real), 5.0) and np.isclose(
    l2p(shifted, real, np.ones(6) * 2), 5.0 * np.sqrt(2) / 2
  )  # one frame vector
  assert npss(np.cumsum(real, 1), real) > npss(real + 0.01, real)  # other frequencies score worse
  still = np.zeros((1, 10, 2, 3))
  sliding = still.copy()
  sliding[0, :, 0, 0] = np.arange(10) * 0.1  # foot 0 slides 0.1 a frame on the floor
  assert foot_skate(still, [0, 1], [0.0], 0.1) == 0
  assert np.isclose(foot_skate(sliding, [0, 1], [0.0], 0.1), 0.05)  # two feet, one sliding
  sliding[0, :, 0, 1] = 0.5  # far above the floor: no skating
  assert foot_skate(sliding, [0, 1], [0.0], 0.1) == 0


def test_benchmark_on_the_held_out_take_ranks_the_baselines(setup):
  _cfg, ds, space = setup
  std = lafan1.window_std(ib.training_takes(ds, ()), space, 10)
  res = lafan1.benchmark(
    {"zero": lafan1.zero_velocity, "linear": lafan1.linear},
    ib.held_out_takes(ds),
    space,
    ds.features.skeleton.feet,
    10,
    std,
  )
  for n in lafan1.BENCHMARK_LENGTHS:
    assert res["linear"][n]["l2p"] < res["zero"][n]["l2p"]
    assert res["linear"][n]["arrival_step"] < 1.0 < res["zero"][n]["arrival_step"]
  assert res["linear"][5]["l2p"] < res["linear"][30]["l2p"] < res["linear"][45]["l2p"]


def test_bad_inbetween_input_is_refused(trained, tmp_path, capsys):
  workdir, _ = trained
  out = tmp_path / "x.csv"
  base = ["inbetween", str(workdir), "--from", f"{TAKE}:0:6", "-o", str(out)]
  assert cli.main([*base, "--to", f"{TAKE}:99999", "--frames", "5"]) == 2
  assert "frame 99999" in capsys.readouterr().err
  assert (
    cli.main([*base, "--to", f"{TAKE}:10", "--to", f"{TAKE}:20", "--frames", "5", "--frames", "6", "--frames", "7"])
    == 2
  )
  assert "one count for every --to" in capsys.readouterr().err
  assert cli.main([*base, "--to", f"{TAKE}:10", "--frames", "0"]) == 2
  capsys.readouterr()
  assert cli.main([*base, "--to", f"{TAKE}:10", "--frames", "1000000000"]) == 2  # was a native abort
  assert "--frames 1000000000 x --num 1: needs about" in capsys.readouterr().err
  point = tmp_path / "point.csv"  # every joint at one point: wrote a transition of zeros
  point.write_text(("0," * 47 + "0\n") * 20)
  from_point = ["inbetween", str(workdir), "--from", f"{point}:0:6", "--to", f"{TAKE}:10", "--frames", "5"]
  assert cli.main([*from_point, "-o", str(out)]) == 2
  assert "frame 0 has every joint at one point" in capsys.readouterr().err
  assert cli.main([*base, "--to", f"{point}:3", "--frames", "5"]) == 2
  assert "--to" in capsys.readouterr().err
  assert cli.main([*base, "--to", f"{TAKE}:\u00b2", "--frames", "5"]) == 2  # int() of a superscript digit
  assert "Traceback" not in capsys.readouterr().err
  assert not out.exists()
  assert cli.main(["sample", str(workdir), "-o", str(out)]) == 2
  assert "use `chorjax inbetween`" in capsys.readouterr().err
  assert cli.main(["export", str(workdir), "-o", str(tmp_path / "d.onnx")]) == 2  # no dance of its own to export
  assert "use `chorjax inbetween`" in capsys.readouterr().err and not list(tmp_path.glob("d.*"))
  bad = tmp_path / "bad.toml"
  bad.write_text('[model]\nfamily = "inbetween"\n[inbetween]\nmin_frames = 40\nmax_frames = 30\n')
  assert cli.main(["train", str(bad), "--workdir", str(tmp_path / "never")]) == 2
  assert "inbetween.min_frames" in capsys.readouterr().err and not (tmp_path / "never").exists()


# ---------------------------------------------------------------- the cvae system (Tang et al. 2022)

CVAE = [
  "inbetween.system=cvae",
  "inbetween.manifold_encoder_sizes=[32]",
  "inbetween.expert_sizes=[32,32]",
  "inbetween.gate_sizes=[32]",
  "inbetween.experts=3",
  "inbetween.latent_size=8",
  "inbetween.manifold_frames=6",
  "inbetween.manifold_steps=40",
  "inbetween.sampling_ramp=20",
  "inbetween.physics_start=20",
  "train.num_steps=80",
  "optim.name=amsgrad",
  "optim.b1=0.5",
  "optim.b2=0.9",
]


@pytest.fixture(scope="module")
def cvae_setup(setup):
  from chorjax.families.inbetween import cvae_training as cvae

  _, ds, space = setup
  cfg = tiny_config(*IB, *CVAE)
  state, spec = ib.create_inbetween_state(cfg, ds.features)
  sampler = ib.TransitionSampler(ib.training_takes(ds, ()), space, cfg.inbetween, 8, seed=0)
  batch = {k: jnp.asarray(v) for k, v in sampler.batch(0).items()}
  assert isinstance(spec, cvae.CvaeSpec)
  return cfg, state, spec, batch


def test_cvae_schedules_sampling_chance_loss_ramp_and_learning_rate(cvae_setup):
  from chorjax.families.inbetween import cvae_training as cvae

  _, _, spec, _ = cvae_setup  # manifold_steps 40, sampling_ramp 20, physics_start 20
  p = [float(cvae.own_frame_chance(s, spec)) for s in (0, 10, 20, 30)]
  assert p == [0.0, 0.5, 1.0, 1.0]
  ramp = [float(cvae.physics_ramp(s, spec)) for s in (0, 19, 20, 30, 40, 60)]
  assert ramp == [0.0, 0.0, 0.0, 0.5, 1.0, 1.0]
  lr = cvae.stage1_schedule(1e-3, 0.1, 20, 40)
  assert np.isclose(lr(0), 1e-3) and np.isclose(lr(19), 1e-4, rtol=0.1)  # decayed to 1e-4 ...
  assert float(lr(20)) < 1e-5 and np.isclose(lr(30), 5e-4) and np.isclose(lr(40), 1e-3)  # ... re-warmed from 0


def _run_steps(state, batch, spec, steps):
  for _ in range(steps):
    state, metrics = ib.inbetween_train_step(state, batch, jax.random.key(1), spec)
  return state, metrics


def test_cvae_decoder_uses_z_and_stage_two_leaves_it_bit_identical(cvae_setup):
  from chorjax.families.inbetween.cvae_model import split

  _cfg, state, spec, batch = cvae_setup
  state = jax.tree.map(jnp.copy, state)  # the fixture's arrays stay (train steps donate theirs)
  state, m1 = _run_steps(state, batch, spec, 40)  # all of stage 1
  assert float(m1["recon"]) > 0 and float(m1["pose_l1"]) == 0
  manifold = nnx.merge(spec.manifold_def, state["params"]["manifold"])
  prev = batch["window"][:, 3]
  rel, _ = split(prev, spec.root)
  step = prev - batch["window"][:, 2]
  root = jnp.zeros((8, 3))
  z1, z2 = jnp.zeros((8, 8)), jnp.ones((8, 8))
  change = jnp.abs(manifold.decode(z1, rel, step, root)[0] - manifold.decode(z2, rel, step, root)[0]).mean()
  moved = jnp.abs(manifold.decode(z1, rel, step, root)[0] - rel).mean()
  assert float(change) > 0.05 * float(moved)  # a decoder that ignored z (posterior collapse) fails here
  before = jax.tree.map(np.asarray, state["params"]["manifold"])
  sampler_before = jax.tree.map(np.asarray, state["params"]["sampler"])
  state, m2 = _run_steps(state, batch, spec, 5)  # stage 2
  assert float(m2["pose_l1"]) > 0 and float(m2["recon"]) == 0
  after = jax.tree.map(np.asarray, state["params"]["manifold"])
  assert all(np.array_equal(a, b) for a, b in zip(jax.tree.leaves(before), jax.tree.leaves(after)))
  moved = [
    not np.array_equal(a, b)
    for a, b in zip(jax.tree.leaves(sampler_before), jax.tree.leaves(state["params"]["sampler"]))
  ]
  assert any(moved)


def test_cvae_run_trains_both_stages_and_writes_transitions(setup, tmp_path):
  workdir = tmp_path / "cvae"
  cfg = tiny_config(*IB, *CVAE, "train.eval_every=40", "sample.frames=20")
  summary = train_and_evaluate(cfg, workdir)
  assert summary["final_step"] == 80 and np.isfinite(summary["final_val_loss"])
  run = load_run(workdir)
  from chorjax.sample import read_phrase

  real = read_phrase(str(TAKE), run.features, run.config.data)
  write = lambda seed: ib.write_transitions(
    run.graphdef, run.params, run.features, run.config.inbetween, real[:6], [real[30]], [12], jax.random.key(seed)
  )[0]
  a, b = write(0), write(1)
  assert a.shape == (6 + 12 + 1, 16, 3) and np.array_equal(a[:6], real[:6]) and np.array_equal(a[-1], real[30])
  assert not np.allclose(a[6:18], b[6:18])  # the latents are drawn: another seed, another transition
