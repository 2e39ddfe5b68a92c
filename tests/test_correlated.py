"""``model.mdn_memory``: the MDN carries the residuals of the frames before into each frame's means. The loss
conditions every frame on what the draw carries, a prime hands its residuals to the draw, and the model's own
draw (``--plain``) of such a run is smoother than a white-noise run's."""

import collections
import dataclasses
import json
from pathlib import Path

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


def test_fed_back_frames_carry_their_own_residuals_and_none_fed_back_is_teacher_forcing():
  """Training with feedback on a model that carries residuals: with nothing fed back the loss is the
  teacher-forced one; with every frame its own, it is the loss of the real targets under the frames drawn and
  fed, each own frame drawn carrying the residuals of the frames fed before it (and another loss)."""
  from chorjax.data.dataset import WindowSampler
  from chorjax.families.recurrent.steps import Feedback, _feedback_loss_fn, _loss_fn, create_train_state

  cfg = tiny_config("model.mdn_memory=2", "data.representation=canonical")
  ds = load_dataset(cfg.data)
  state, spec = create_train_state(cfg, ds.features.dim, ds.num_motions)
  batch = WindowSampler(ds.train, cfg.data.seq_length, 4, seed=0).batch(0)
  key, step = jax.random.key(1), jnp.asarray(5)
  fb = lambda fraction: Feedback("scheduled", 2, 3, fraction, 0, 0, "sample", 1.0, 1.0)
  spec = dataclasses.replace(spec, input_noise=0.0, dropout=0.0, feedback=fb(0.0))
  teacher = float(_loss_fn(state["params"], batch, key, spec)[0])
  assert float(_feedback_loss_fn(state["params"], batch, key, step, spec)[0]) == pytest.approx(teacher, rel=1e-5)
  own = float(_feedback_loss_fn(state["params"], batch, key, step, dataclasses.replace(spec, feedback=fb(1.0)))[0])
  assert np.isfinite(own) and own != pytest.approx(teacher, rel=1e-3)


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


def _carried_roots(head, out):
  """The moduli of the roots of the autoregression ``head.carried`` applies to the residuals, per coordinate
  of the first component: each lag's coefficient read off by carrying a unit residual at that lag alone."""
  zeros = [jnp.zeros((1, head.num_mixtures, head.dim))] * head.memory
  base = head.carried(out, zeros)[1][0, 0]
  phi = [head.carried(out, [z + (k == lag) for k, z in enumerate(zeros)])[1][0, 0] - base for lag in range(head.memory)]
  coeffs = np.stack([np.ones(head.dim), *[-np.asarray(p) for p in phi]], axis=1)  # z^M - phi_1 z^(M-1) - ...
  return np.array([np.abs(np.roots(c)).max() for c in coeffs])


def test_a_carry_within_a_radius_keeps_every_root_of_its_autoregression_within_it():
  """``model.mdn_radius``: whatever the network outputs, what the residuals keep doing fades at least as fast
  as radius^t (every root of the carried autoregression within the radius), where the same outputs with no
  radius carry a deviation for longer."""
  model, window = _model_and_window(4, memory=3)
  out = model(window[:, :-1], jnp.zeros((1,), jnp.int32))[:, 2] * 4.0  # outputs far from zero: partials near +-1
  head = model.head
  unbounded = _carried_roots(head, out)
  head.radius = 0.8
  bounded = _carried_roots(head, out)
  assert unbounded.max() > 0.9 and bounded.max() <= 0.8 + 1e-4
  np.testing.assert_allclose(bounded, 0.8 * unbounded, rtol=1e-3)  # every root scaled by the radius
  cfg = tiny_config("model.mdn_memory=3", "model.mdn_radius=0.8")
  assert create_model(cfg.model, head.dim, 2, seed=0).head.radius == 0.8


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


def _files_the_value_enters(value: float, argv: list) -> tuple[dict, collections.Counter]:
  """``{file: functions}`` of the package's functions called with ``value`` among their arguments (itself, in a
  dict, or as a record's or a namespace's ``pace``, or a given flag's ``value``) while ``chorjax ARGV`` runs:
  where a control travels; and ``{function: calls}``."""
  import argparse
  import dataclasses
  import sys

  def holds(v, depth=0):
    if isinstance(v, float):
      return v == value
    if isinstance(v, dict) and depth == 0:
      return any(holds(x, 1) for x in v.values())
    record = isinstance(v, argparse.Namespace) or (dataclasses.is_dataclass(v) and not isinstance(v, type))
    return record and value in (getattr(v, "pace", None), getattr(v, "value", None))

  files: dict = {}
  calls: collections.Counter = collections.Counter()
  package = str(Path(cli.__file__).parent)

  def profile(frame, event, _):
    name = frame.f_code.co_filename
    if event == "call" and name.startswith(package) and any(holds(v) for v in list(frame.f_locals.values())):
      files.setdefault("chorjax" + Path(name).as_posix()[len(package) :], set()).add(frame.f_code.co_name)
      calls[frame.f_code.co_name] += 1

  sys.setprofile(profile)
  try:
    assert cli.main(argv) == 0
  finally:
    sys.setprofile(None)
  return files, calls


def test_a_control_goes_from_its_flag_to_where_it_acts_through_six_files(tmp_path):
  """``chorjax sample RUN --pace G``: the value, followed through every function it is handed to, reaches the
  pace governor through the command line (its flag made in cli_parser from the controls' table), the sample,
  the run's resolution, the controls' home and the generator; besides that route it is only checked against
  the table and written beside the sample."""
  common = [*TINY, "train.num_steps=10", "model.hidden_size=16", "data.seq_length=24", "train.batch_size=4"]
  common += ["data.representation=canonical", "train.calibrate=false", "log.tensorboard=false"]
  train_and_evaluate(tiny_config(*common, "model.mdn_memory=2"), tmp_path / "run")
  gain = 1.2345
  files, calls = _files_the_value_enters(
    gain, ["sample", str(tmp_path / "run"), "-o", str(tmp_path / "s.csv"), "--frames", "20", "--pace", str(gain)]
  )
  assert "_governed" in files["chorjax/families/recurrent/generation.py"]  # where it acts
  checks = {"chorjax/sampling/table.py", "chorjax/fields.py"}  # validated as the config key is
  assert all(n.startswith("check_") for f in checks & files.keys() for n in files[f])
  assert calls["check_sample_control"] == 1  # validated once
  route = sorted(set(files) - checks - {"chorjax/io/output.py"})  # the sample's settings written beside it
  assert route == [
    "chorjax/cli.py",
    "chorjax/families/recurrent/generation.py",
    "chorjax/run.py",
    "chorjax/sample.py",
    "chorjax/sampling/controls.py",
  ], route  # with chorjax/cli_parser.py, where the flag is made: six files


def test_what_a_correlated_draw_cannot_be_given_is_refused_in_one_line(tmp_path, capsys):
  """Training that feeds back its mixture mean (a carried draw feeds back what it draws) and ``--plain`` beside
  a draw flag are refused, exit 2, one line, nothing written."""
  code = cli.main(
    [
      "train",
      "configs/quickstart.toml",
      "model.mdn_memory=2",
      "train.feedback=auto",
      "train.feedback_draw=mean",
      "--workdir",
      str(tmp_path / "r"),
    ]
  )
  err = capsys.readouterr().err
  assert code == 2 and "train.feedback_draw" in err and len(err.strip().splitlines()) == 1
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
