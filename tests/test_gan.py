"""The LSTM-GAN family: shapes, the critic and generator steps on real cmu94 windows, no gradient leaking
between the two, the gradient penalty's second derivative, unit bone directions, exact resume, and the
run sampled, evaluated and compared like the other families."""

import json
import shutil

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import nnx
from helpers import GAN_NETWORKS, read_events, tiny_config

from chorjax import cli
from chorjax.config import load_config
from chorjax.data.dataset import WindowSampler, load_dataset
from chorjax.errors import UserError
from chorjax.evaluation.scoring import mean_of
from chorjax.families.gan.adversarial import create_gan_state, critic_loss, critic_step, generator_loss, generator_step
from chorjax.families.gan.networks import Critic, GanModel, Generator, pose_layer
from chorjax.models.rnn import RecurrentCore
from chorjax.run import load_run
from chorjax.training.driver import train_and_evaluate

GAN = [
  *GAN_NETWORKS,
  "gan.generator_lr=3e-3",
  "gan.critic_lr=3e-3",
]


@pytest.fixture(scope="module")
def setup():
  cfg = tiny_config(*GAN)
  ds = load_dataset(cfg.data)
  sampler = WindowSampler(ds.train, cfg.data.seq_length, 8, 0)
  return cfg, ds, jnp.asarray(sampler.batch(0)["inputs"])


@pytest.fixture(scope="module")
def fresh(setup):
  """A fresh GAN state and spec on the tiny config (bce)."""
  cfg, ds, _ = setup
  return create_gan_state(cfg, ds.features)


def test_generator_and_critic_shapes_at_any_length(setup):
  cfg, ds, real = setup
  gen, critic = (
    Generator(cfg.gan, ds.features.dim, rngs=nnx.Rngs(0)),
    Critic(cfg.gan, ds.features.dim, rngs=nnx.Rngs(1)),
  )
  z = jax.random.normal(jax.random.key(0), (3, cfg.gan.latent_size))
  for frames in (cfg.data.seq_length, 5 * cfg.data.seq_length):  # unrolls past the training length
    x = gen(z, frames)
    assert x.shape == (3, frames, ds.features.dim) and bool(jnp.isfinite(x).all())
    assert critic(x).shape == (3,)
  assert critic(real).shape == (real.shape[0],)


def test_one_critic_step_lowers_its_loss_and_leaves_the_generator_alone(setup, fresh):
  real = setup[2]
  state, spec = fresh
  key = jax.random.key(3)
  before = critic_loss(state["params"]["critic"], state["params"]["generator"], real, key, spec)[0]
  new, _ = critic_step(state, real, key, spec)
  after = critic_loss(new["params"]["critic"], new["params"]["generator"], real, key, spec)[0]
  assert float(after) < float(before)
  for part in ("params", "opt_state"):  # the generator's half is bit-identical
    for a, b in zip(jax.tree.leaves(state[part]["generator"]), jax.tree.leaves(new[part]["generator"])):
      np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
  # and the critic's loss has no gradient into the generator at all (generated sequences enter stopped)
  grads = jax.grad(critic_loss, argnums=1, has_aux=True)(
    state["params"]["critic"], state["params"]["generator"], real, key, spec
  )[0]
  assert all(float(jnp.abs(g).max()) == 0.0 for g in jax.tree.leaves(grads))


@pytest.mark.parametrize("loss", ["bce", "wgan-gp"])
def test_a_generator_step_lowers_its_loss_with_the_critic_frozen(setup, fresh, loss):
  _cfg, ds, real = setup
  state, spec = fresh
  if loss == "wgan-gp":
    state, spec = create_gan_state(tiny_config(*GAN, f"gan.loss={loss!r}"), ds.features)
  key = jax.random.key(5)
  g_loss = lambda s: float(generator_loss(s["params"]["generator"], s["params"]["critic"], key, 8, 12, spec))
  new, metrics = generator_step(state, key, 8, 12, spec)
  assert g_loss(new) < g_loss(state) and float(metrics["gen_loss"]) == pytest.approx(g_loss(state), rel=1e-5)
  for a, b in zip(jax.tree.leaves(state["params"]["critic"]), jax.tree.leaves(new["params"]["critic"])):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
  if loss == "wgan-gp":  # the critic's update logs its two terms
    metrics = critic_step(state, real, key, spec)[1]
    assert float(metrics["gradient_penalty"]) > 0 and np.isfinite(float(metrics["wasserstein"]))


def test_the_gradient_penalty_differentiates_through_the_fused_layers_as_through_a_plain_scan():
  """WGAN-GP needs the critic's parameter gradient of its input gradient: the fused layers' custom
  backward pass must give the same second derivative as ``lax.scan`` over the cell's step."""
  core = RecurrentCore("lnlstm", 5, 8, 1, 1, initial_state="zero", rngs=nnx.Rngs(0))
  graphdef, params = nnx.split(core, nnx.Param)
  x = jax.random.normal(jax.random.key(1), (3, 7, 5))

  def score(p, x, fused):
    m = nnx.merge(graphdef, p)
    carry = m.initial_carry(jnp.ones((3, 1)))
    if fused:
      h = m(x, carry)[0]
    else:
      h = jnp.swapaxes(jax.lax.scan(m.step, carry, jnp.swapaxes(x, 0, 1))[1], 0, 1)
    return jnp.sin(h[:, -1]).sum()

  penalty = lambda p, fused: jnp.sum(jax.grad(score, argnums=1)(p, x, fused) ** 2)
  a, b = (jax.jit(jax.grad(penalty), static_argnums=1)(params, fused) for fused in (True, False))
  for u, v in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
    np.testing.assert_allclose(np.asarray(u), np.asarray(v), rtol=2e-3, atol=1e-5 * float(jnp.abs(v).max()))


def test_generated_bones_are_unit_directions_at_the_takes_lengths(setup, fresh):
  ds = setup[1]
  state, spec = fresh
  model = nnx.merge(spec.graphdef, state["params"])
  assert isinstance(model, GanModel) and spec.projection is not None
  from chorjax.families.gan.networks import fake_sequences

  x = fake_sequences(model.generator, jax.random.key(0), 2, 30, spec.projection)
  raw = np.asarray(x) * ds.features.std + ds.features.mean
  dirs = np.stack([raw[..., s : s + 3] for s in spec.projection.starts], -2)
  np.testing.assert_allclose(np.linalg.norm(dirs, axis=-1), 1.0, atol=1e-4)
  pos = np.asarray(ds.features.decode(x[0]))
  sk = ds.features.skeleton
  for j, p in enumerate(sk.parents):
    if p >= 0:
      np.testing.assert_allclose(
        np.linalg.norm(pos[:, j] - pos[:, p], axis=-1), ds.features.lengths[j] / ds.features.scale, rtol=1e-3
      )


def test_bad_gan_configs_are_refused_before_anything_is_written(tmp_path):
  for extra, fragment in (
    (["data.representation=canonical"], "gan.pose = 'directions' needs data.representation = 'directions'"),
    (["gan.critic_dense=[0]"], "gan.critic_dense: expected a list of positive layer sizes"),
    (["train.feedback=auto", "model.dropout=0"], "train.feedback"),
  ):
    with pytest.raises(UserError, match=fragment.replace("(", r"\(").replace(".", r"\.")):
      train_and_evaluate(tiny_config(*GAN, *extra), tmp_path / "w")
    assert not (tmp_path / "w").exists()


def test_resume_is_exact_and_the_run_samples_evaluates_and_compares(tmp_path, capsys):
  overrides = [*GAN, "gan.critic_steps=2", "train.num_steps=4", "train.checkpoint_every=2", "train.log_every=2"]
  straight, resumed = tmp_path / "straight", tmp_path / "resumed"
  train_and_evaluate(tiny_config(*overrides), straight)
  shutil.copytree(straight, resumed)  # the same run as if killed after its step-2 checkpoint
  shutil.rmtree(resumed / "checkpoints" / "4")
  summary = train_and_evaluate(tiny_config(*overrides), resumed)
  assert summary["start_step"] == 2 and summary["final_step"] == 4
  for a, b in zip(jax.tree.leaves(load_run(straight).params), jax.tree.leaves(load_run(resumed).params)):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
  rows = [json.loads(l) for l in (straight / "metrics.jsonl").read_text().splitlines()]
  assert {"gen_loss", "critic_loss", "d_real", "d_fake"} <= set(rows[-1]) and rows[-1]["step"] == 4
  scalars, _ = read_events(next(straight.glob("events.out.tfevents.*")))
  assert [s for s, _ in scalars["train/gen_loss"]] == [2, 4] and "train/critic_loss" in scalars

  out = tmp_path / "s.npz"  # far past the 12-frame training windows, two different dancers
  assert cli.main(["sample", str(straight), "-o", str(out), "--frames", "60", "--num", "2"]) == 0
  with np.load(out) as f:
    pos = f["positions"]
  assert pos.shape[:2] == (2, 60) and not np.allclose(pos[0], pos[1])
  assert (
    cli.main(["sample", str(straight), "-o", str(tmp_path / "p.csv"), "--prime", "cmu94/94_10_skeleton_3d.csv"]) == 2
  )
  assert "cannot continue a phrase" in capsys.readouterr().err
  for flag in (["--motion", "1"], ["--mix", "0=1"]):  # conditioned on nothing: refused, not the same bytes
    assert cli.main(["sample", str(straight), "-o", str(tmp_path / "m.csv"), *flag]) == 2
    assert "draws from noise alone" in capsys.readouterr().err and not (tmp_path / "m.csv").exists()

  assert cli.main(["eval", str(straight), "--data", "cmu94", "--frames", "120", "--num", "2"]) == 0
  result = json.loads((straight / "eval" / "metrics.json").read_text())
  assert result["heldout_loss"] is None and result["loss_kind"] == "none" and mean_of(result["movement_first"]) > 0
  assert result["sampling"]["persistence"] == 0.0  # the MDN draw controls are recorded as off
  report = tmp_path / "report.md"
  assert cli.main(["compare", str(straight), "-o", str(report)]) == 0
  assert "gan (bce)" in report.read_text()


def test_the_shipped_gan_config_is_a_gan_on_bone_directions():
  from pathlib import Path

  cfg = load_config(Path(__file__).resolve().parents[1] / "configs" / "gan.toml")
  assert (cfg.model.family, cfg.gan.pose, cfg.data.representation) == ("gan", "directions", "directions")


def test_rotations_go_through_forward_kinematics_down_the_chain(setup):
  """``gan.pose = "rotations"``: identity quaternions give the rest directions; a turn of the root alone
  turns every bone (each joint's rotation is its parent's times its own); any output gives unit bones."""
  ds = setup[1]
  kin = pose_layer(ds.features, "rotations")
  sk, j = ds.features.skeleton, ds.features.skeleton.num_joints
  rest = np.asarray(kin.rest).reshape(j, 3)
  identity = np.zeros((1, 4 + 4 * j), np.float32)
  identity[0, 4::4] = 1.0
  half = np.sqrt(0.5)
  turned = identity.copy()
  turned[0, 4 + 4 * sk.root : 8 + 4 * sk.root] = [half, 0.0, half, 0.0]  # 90 degrees about y (up)
  random = np.asarray(jax.random.normal(jax.random.key(0), (1, 4 + 4 * j)))
  raw = lambda out: (np.asarray(kin(jnp.asarray(out))) * ds.features.std + ds.features.mean)[0, 3:].reshape(j, 3)
  bones = [b for b in range(j) if b != sk.root]
  np.testing.assert_allclose(raw(identity)[bones], rest[bones], atol=1e-5)
  about_y = rest[bones] @ np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])  # x -> -z, z -> x
  np.testing.assert_allclose(raw(turned)[bones], about_y, atol=1e-5)
  np.testing.assert_allclose(np.linalg.norm(raw(random)[bones], axis=-1), 1.0, atol=1e-5)
