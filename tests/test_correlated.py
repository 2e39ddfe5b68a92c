"""``model.mdn_memory``: the MDN carries the residuals of the frames before into each frame's means. The loss
conditions every frame on what the draw carries, a prime hands its residuals to the draw, and the model's own
draw (``--plain``) of such a run is smoother than a white-noise run's."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import nnx
from helpers import TINY, tiny_config

from chorjax import cli
from chorjax.data.dataset import load_dataset
from chorjax.evaluation.metrics import roughness
from chorjax.families.recurrent.recurrent_model import create_model
from chorjax.models.heads import ar_coefficients, mdn_carry, mdn_log_prob
from chorjax.sampling.controls import PLAIN
from chorjax.training.driver import train_and_evaluate


def _model_and_window(frames: int = 20, memory: int = 2):
  """A tiny model carrying ``memory`` residuals (random weights, PCA-free) and a real window of cmu94
  (normalized features)."""
  cfg = tiny_config(f"model.mdn_memory={memory}", "data.representation=canonical")
  ds = load_dataset(cfg.data)
  model = create_model(cfg.model, ds.features.dim, ds.num_motions, seed=0)
  _, z = ds.train[0]
  return model, jnp.asarray(z[None, : frames + 1], jnp.float32)


@pytest.mark.parametrize("memory", [1, 2, 3])
def test_the_loss_conditions_each_frame_on_the_residuals_the_draw_carries(memory):
  """The window's NLL equals the frames' log-likelihoods taken one after another, each under the mixture
  ``carried`` with the residuals of the targets before (none before the first), as the draw steps."""
  model, window = _model_and_window(memory=memory)
  out = model(window[:, :-1], jnp.zeros((1,), jnp.int32))
  head, u = model.head, model.head.to_basis(window[:, 1:])
  memory = model.draw_start(window[:, :1])[2:]
  assert all(float(jnp.abs(m).max()) == 0 for m in memory)  # nothing before the first frame
  per_frame = []
  for t in range(u.shape[1]):
    per_frame.append(mdn_log_prob(*head.carried(out[:, t], memory), u[:, t]))
    memory = (head.residual(out[:, t], u[:, t]), *memory[:-1])
  loss = float(model.loss(out, window[:, 1:])[0])
  np.testing.assert_allclose(loss, -float(jnp.mean(jnp.stack(per_frame))), rtol=1e-5)
  # the residuals matter: the same outputs read as white noise are another likelihood
  white = -float(jnp.mean(mdn_log_prob(*head.params(out), u)))
  assert abs(white - loss) > 1e-3 * abs(loss)


@pytest.mark.parametrize("memory", [1, 3])
def test_a_drawn_frame_is_the_carried_mean_plus_its_scale_and_its_residual_is_remembered(memory):
  """One draw step: the frame is the drawn component's carried mean plus scale x noise, and the state keeps
  its residual and the ones before."""
  model, window = _model_and_window(4, memory)
  out = model(window[:, :-1], jnp.zeros((1,), jnp.int32))
  head = model.head
  state = model.draw_start(window[:, :4], out[:, :3])  # after a four-frame prime
  gumbel = jnp.array([[50.0, 0.0, 0.0]])  # component 0
  noise = jax.random.normal(jax.random.key(1), (1, model.dim))
  x, (comp, _, *memory) = head.draw(out[:, 3], gumbel, noise, state)
  _, mu, scale = head.carried(out[:, 3], state[2:])
  np.testing.assert_allclose(head.to_basis(x), mu[:, 0] + scale[:, 0] * noise, atol=1e-5)
  assert int(comp[0]) == 0
  np.testing.assert_allclose(memory[0], head.residual(out[:, 3], head.to_basis(x)), atol=1e-5)
  for newer, older in zip(memory[1:], state[2:]):  # the others move one place back
    np.testing.assert_array_equal(newer, older)
  # a prime's residuals are those the loss carries into the frame after it
  hist = head.history(out, head.to_basis(window[:, 1:]))
  for held, carried in zip(state[2:], hist):
    np.testing.assert_allclose(held, carried[:, 3], atol=1e-6)


@pytest.mark.parametrize("memory", [1, 2, 3])
def test_a_smooth_carry_never_gains_power_at_the_highest_frequency(memory):
  """``model.mdn_carry = "smooth"``: whatever the network outputs, each lag's partial autocorrelation is in
  (-1, 1) and the autoregression's polynomial at -1 is at least 1 (its power at a sign flip every frame at most
  white noise's), lags of either sign still reached; ``"free"`` reaches below 1."""
  raw = 2.0 * jax.random.normal(jax.random.key(0), (20_000, memory * 5))
  for smooth in (True, False):
    partial = mdn_carry(raw, 5, memory, smooth)
    assert partial.shape == (20_000, memory, 1, 5) and float(jnp.abs(partial).max()) < 1
    phi = ar_coefficients(list(jnp.moveaxis(partial, -3, 0)))
    at_nyquist = 1 - sum(p * (-1.0) ** (k + 1) for k, p in enumerate(phi))  # 1 - sum_k phi_k (-1)^k
    if smooth:
      assert float(at_nyquist.min()) >= 1 - 1e-4
      if memory > 1:  # the later lags take either sign
        assert float(partial[:, 1:].min()) < -0.2 and float(partial[:, 1:].max()) > 0.2
    else:
      assert float(at_nyquist.min()) < 0.5


def _plain_jitter(run_dir, tmp_path, name: str) -> float:
  """The jitter of 400 frames of ``chorjax sample RUN --plain``, whose settings say every draw control is off."""
  out = tmp_path / f"{name}.npz"
  assert cli.main(["sample", str(run_dir), "--plain", "--frames", "400", "-o", str(out), "--seed", "1"]) == 0
  with np.load(out) as f:
    settings, pos = json.loads(str(f["meta"]))["settings"], f["positions"][0]
  assert {k: settings[k] for k in PLAIN} == PLAIN
  return roughness(pos)


def test_the_plain_draw_of_a_correlated_run_is_smoother_than_a_white_runs(tmp_path):
  """Trained alike for 150 steps on cmu94, the model's own draw (temperatures 1, every control off) trembles
  less than half as much when the MDN carries two residuals as when its noise is white."""
  common = [*TINY, "train.num_steps=150", "model.hidden_size=32", "data.seq_length=24", "train.batch_size=8"]
  common += ["data.representation=canonical", "train.calibrate=false", "log.tensorboard=false"]
  for noise, memory in (("white", 0), ("correlated", 2)):
    train_and_evaluate(tiny_config(*common, f"model.mdn_memory={memory}"), tmp_path / noise)
  white, correlated = (_plain_jitter(tmp_path / n, tmp_path, n) for n in ("white", "correlated"))
  assert correlated < 0.5 * white, (correlated, white)


def test_what_a_correlated_draw_cannot_be_given_is_refused_in_one_line(tmp_path, capsys):
  """Training with own outputs fed back (the draw there carries no residuals) and ``--plain`` beside a draw
  flag are refused, exit 2, one line, nothing written."""
  code = cli.main(
    [
      "train",
      "configs/quickstart.toml",
      "model.mdn_memory=2",
      "train.feedback=auto",
      "--workdir",
      str(tmp_path / "r"),
    ]
  )
  err = capsys.readouterr().err
  assert code == 2 and "train.feedback" in err and len(err.strip().splitlines()) == 1
  assert not (tmp_path / "r").exists()
  code = cli.main(
    ["sample", str(tmp_path / "r"), "-o", str(tmp_path / "s.csv"), "--plain", "--set", "sample.noise_smoothing=0.5"]
  )
  err = capsys.readouterr().err
  assert code == 2 and "--plain" in err and "sample.noise_smoothing" in err


@pytest.mark.parametrize("prime", [False, True])
def test_a_correlated_run_samples_live_streams_and_primes(tmp_path, prime):
  """The generator's draw equals the stream's draw chunk by chunk (the residuals carried across chunks)."""
  from chorjax.families.recurrent.generation import continue_stream, generate, start_stream
  from chorjax.sampling.controls import Draw

  model, window = _model_and_window(8)
  graphdef, params = nnx.split(model, nnx.Param)
  motion = jnp.zeros((1,), jnp.int32)
  p = window if prime else None
  draw = Draw(noise_order=1)
  whole = generate(graphdef, params, motion, jax.random.key(0), num_frames=6, draw=draw, prime_BxPxD=p)
  state = start_stream(graphdef, params, motion, draw, p)
  state, first = continue_stream(graphdef, params, state, jax.random.key(0), draw, num_frames=6)
  assert np.abs(np.asarray(first) - np.asarray(whole)).max() < 1e-4  # the same program, compiled apart
  assert len(state[3]) == 2 + 2 and float(jnp.abs(state[3][2]).max()) > 0  # the residuals ride in the state


def test_the_quickstart_carries_its_noise_draws_with_three_controls_and_calibrates_two():
  """``configs/quickstart.toml``: an MDN carrying its noise; its draw is the plain draw but for
  three controls, the scale temperature, the pace governor and the clip to the training range (decoding
  aside), and calibration chooses the scale temperature and foot lock."""
  from chorjax.config import load_config
  from chorjax.sampling.calibrate import default_grid
  from chorjax.sampling.controls import PLAIN, Controls

  cfg = load_config("configs/quickstart.toml")
  assert cfg.model.memory == 3 and cfg.model.mdn_carry == "smooth" and cfg.model.mdn_basis == "acceleration"
  assert cfg.train.calibrate and cfg.train.keep == "last" and cfg.train.num_steps == 4000
  drawn = Controls.resolve(cfg.sample).to_dict()
  used = {k for k in PLAIN if drawn[k] != PLAIN[k]} | {"sigma_temperature"}  # calibrated: used at any value
  assert used == {"sigma_temperature", "pace", "clamp"}  # the mixture weights at full temperature
  assert set(default_grid(cfg)) - {"noise_order", "pace"} == {"sigma_temperature", "foot_lock"}
