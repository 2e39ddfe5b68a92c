"""A model family plugs in: a toy family defined only here (its model, train step, draw and stream, and one
registry call) trains, samples, evaluates and streams through the command line and the Python API, with
no edit to any other file. The built-in families are asked the same way."""

import dataclasses
import functools
import json
import os
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest
from flax import nnx
from helpers import tiny_config

import chorjax
from chorjax import cli
from chorjax.families import family_of, get, names, register
from chorjax.families.family import Family

TOY = ["model.family=toy", "train.num_steps=4", "log.tensorboard=false", "train.eval_every=2"]


class Drift(nnx.Module):
  """The toy model: the next frame is the frame plus a learned linear drift."""

  def __init__(self, dim: int, *, rngs: nnx.Rngs):
    self.drift = nnx.Linear(dim, dim, rngs=rngs)

  def __call__(self, x):
    return x + 0.1 * self.drift(x)


@dataclasses.dataclass(frozen=True)
class ToySpec:
  graphdef: object
  tx: optax.GradientTransformation


def _loss(params, batch, graphdef):
  return jnp.mean((nnx.merge(graphdef, params)(batch["inputs"]) - batch["targets"]) ** 2)


@functools.partial(jax.jit, static_argnums=3, donate_argnums=0)
def toy_step(state, batch, key, spec: ToySpec):
  loss, grads = jax.value_and_grad(_loss)(state["params"], batch, spec.graphdef)
  updates, opt_state = spec.tx.update(grads, state["opt_state"], state["params"])
  new = {"params": optax.apply_updates(state["params"], updates), "opt_state": opt_state, "step": state["step"] + 1}
  return new, {"loss": loss}


@functools.partial(jax.jit, static_argnames=("graphdef", "num_frames"))
def _roll(graphdef, params, x_BxD, key, *, num_frames: int, sigma):
  model = nnx.merge(graphdef, params)

  def body(x, k):
    x = model(x) + 0.05 * sigma * jax.random.normal(k, x.shape)
    return x, x

  x, xs = jax.lax.scan(body, x_BxD, jax.random.split(key, num_frames))
  return x, jnp.swapaxes(xs, 0, 1)


def start_stream(graphdef, params, motion, draw, prime_BxPxD=None):
  if prime_BxPxD is None:
    return jnp.zeros((np.shape(motion)[0], params["drift"]["bias"].shape[0]))
  return jnp.asarray(prime_BxPxD[:, -1])


def continue_stream(graphdef, params, state, key, draw, *, num_frames: int):
  return _roll(graphdef, params, state, key, num_frames=num_frames, sigma=draw.sigma_temperature)


class Toy(Family):
  name = "toy"

  def build_model(self, cfg, features, num_motions):
    return Drift(features.dim, rngs=nnx.Rngs(cfg.train.seed))

  def create_state(self, cfg, ds):
    from chorjax.optimizer import create_optimizer

    graphdef, params = nnx.split(self.build_model(cfg, ds.features, ds.num_motions), nnx.Param)
    params = nnx.to_pure_dict(params)
    tx, _ = create_optimizer(cfg)
    return {"params": params, "opt_state": tx.init(params), "step": jnp.zeros((), jnp.int32)}, ToySpec(graphdef, tx)

  def parts(self, cfg, ds):
    from chorjax.data.dataset import WindowSampler, eval_windows

    sampler = WindowSampler(ds.train, cfg.data.seq_length, cfg.train.batch_size, cfg.train.seed)
    val = eval_windows(ds.val, cfg.data.seq_length, cfg.train.val_windows)
    return toy_step, sampler, val, lambda params, val, spec: _loss(params, val, spec.graphdef)

  def window_loss(self, graphdef, params, windows):
    return float(_loss(params, windows, graphdef))

  def dance(self, graphdef, params, features, motion, key, num_frames, controls, prime=None):
    x0 = jnp.zeros((np.shape(motion)[0], features.dim)) if prime is None else jnp.asarray(prime[:, -1])
    _, z = _roll(graphdef, params, x0, key, num_frames=num_frames, sigma=controls.sigma_temperature)
    if prime is not None:
      z = np.concatenate([prime, np.asarray(z)], axis=1)
    return np.asarray(features.decode(z, **controls.decoding()))

  def stream(self):
    return start_stream, continue_stream


register(Toy())


@pytest.fixture(scope="module")
def toy_run(tmp_path_factory):
  """The toy family trained through the API (its end sample written)."""
  workdir = tmp_path_factory.mktemp("toy") / "api"
  return chorjax.train(tiny_config(*TOY), workdir)


def test_a_toy_family_trains_and_samples_through_the_api(toy_run):
  assert toy_run.family.name == "toy" and toy_run.step == 4
  assert (toy_run.workdir / "samples" / "sample.csv").is_file()
  rows = [json.loads(line) for line in (toy_run.workdir / "metrics.jsonl").read_text().splitlines()]
  assert any("val_loss" in r for r in rows)
  dance = toy_run.sample(frames=20, seed=1)
  again = chorjax.load_run(toy_run.workdir).sample(frames=20, seed=1)
  assert dance.positions.shape == (20, 16, 3) and np.isfinite(dance.positions).all()
  np.testing.assert_array_equal(dance.positions, again.positions)  # loaded back, the same draw
  assert not np.allclose(dance.positions, toy_run.sample(frames=20, seed=2).positions)
  with pytest.raises(chorjax.UserError, match="'temprature' is not a sampling control; did you mean"):
    toy_run.sample(frames=5, temprature=0.5)  # a misspelt control is refused, not swallowed


@pytest.mark.parametrize(
  "bad",
  [
    {"frames": 2.5},
    {"frames": "100"},
    {"frames": True},
    {"frames": 10**12},
    {"num": 0},
    {"seed": -1},
    {"seed": 2**32 + 5},
    {"seed": 1.5},
    {"pi_temperature": -1.0},
    {"sigma_temperature": float("nan")},
    {"noise_order": 100},
    {"crossfade": 5.0},
    {"clamp": "no"},
  ],
)
def test_the_api_refuses_what_the_command_line_refuses(toy_run, bad):
  """The same checks as the flags (one validation layer): a UserError, never a traceback from JAX."""
  with pytest.raises(chorjax.UserError):
    toy_run.sample(**{"frames": 5, **bad})


def test_a_toy_family_trains_samples_and_evaluates_through_the_cli(tmp_path, capsys):
  config = tmp_path / "toy.toml"
  config.write_text(cli_toml())
  workdir = tmp_path / "cli"
  assert cli.main(["train", str(config), *TOY, "--workdir", str(workdir)]) == 0
  out = tmp_path / "dance.csv"
  assert cli.main(["sample", str(workdir), "-o", str(out), "--frames", "30", "--sigma-temperature", "0.5"]) == 0
  assert np.loadtxt(out, delimiter=",").shape == (30, 48)
  assert cli.main(["eval", str(workdir), "--data", "cmu94", "--frames", "120", "--num", "2"]) == 0
  metrics = json.loads((workdir / "eval" / "metrics.json").read_text())
  assert metrics["loss_kind"] == "nll" and np.isfinite(metrics["heldout_loss"])  # its own window loss
  between = ["inbetween", str(workdir), "--from", "x", "--to", "y", "--frames", "3", "-o", str(tmp_path / "i.csv")]
  assert cli.main(between) == 2
  assert "not an in-betweening run" in capsys.readouterr().err


def cli_toml() -> str:
  from chorjax.config import to_toml

  return to_toml(tiny_config())


def test_a_toy_family_streams_through_the_api_and_the_live_command(toy_run):
  from websockets.sync.client import connect

  from chorjax.live.server import Stream
  from chorjax.models import motion_weight_vector

  sampling = toy_run.sampling()
  stream = Stream(toy_run, sampling, motion_weight_vector(toy_run.num_motions), seed=0, chunk=4)
  frames = np.concatenate([stream.next_chunk() for _ in range(3)])
  assert frames.shape == (12, 16, 3) and np.isfinite(frames).all()
  # the command, in a process that registers the toy family as this file does
  here = Path(__file__).resolve().parent
  code = "import sys, test_families; from chorjax.cli import main; sys.exit(main(sys.argv[1:]))"
  env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(here), os.environ.get("PYTHONPATH", "")])}
  proc = subprocess.Popen(
    [sys.executable, "-c", code, "live", str(toy_run.workdir), "--port", "0", "--fps", "30"],
    stdout=subprocess.PIPE,
    stderr=subprocess.PIPE,
    text=True,
    env=env,
  )
  try:
    assert proc.stdout is not None
    line = proc.stdout.readline()
    assert line.startswith("serving http://"), (line, proc.stderr.read() if proc.stderr else "")
    with connect(line.split()[1].replace("http://", "ws://") + "/ws") as ws:
      assert json.loads(ws.recv())["hello"]["joints"] == 16
      got = [json.loads(ws.recv()) for _ in range(10)]
    assert [m["frame"] for m in got] == list(range(got[0]["frame"], got[0]["frame"] + 10))
    assert all(np.isfinite(m["positions"]).all() for m in got)
  finally:
    proc.terminate()
    proc.wait(timeout=30)


def test_the_registry_names_every_family_and_asks_each_what_it_serves():
  assert {"rnn", "gan", "inbetween", "patch", "toy"} <= set(names())
  assert get("gan").refusal("live") and get("inbetween").refusal("sample") and get("rnn").refusal("sample") is None
  assert get("toy").refusal("inbetween") and get("toy").refusal("sample") is None
  assert not get("gan").likelihood and get("rnn").calibrated and not get("toy").calibrated
  assert family_of(tiny_config("model.family=inbetween")).name == "inbetween"
  assert family_of({"model": {}}).name == "rnn"  # a config saved before model.family existed


def test_an_unknown_family_is_one_line_naming_the_known_ones():
  from chorjax.errors import UserError

  with pytest.raises(UserError, match=r"'gann' is not one of 'rnn', 'gan', 'inbetween'.*did you mean 'gan'"):
    tiny_config("model.family=gann")


def test_the_end_of_a_run_is_the_hooks_handed_to_training(tmp_path):
  from chorjax.training import end_of_run
  from chorjax.training.driver import train_and_evaluate

  seen = []
  hook = lambda run: seen.append(run) or {"mine": str(run.workdir)}
  summary = train_and_evaluate(tiny_config(*TOY), tmp_path / "w", finish=[hook])
  assert summary["samples"] == {"mine": str(tmp_path / "w")} and not (tmp_path / "w" / "samples").exists()
  assert isinstance(seen[0], end_of_run.Finished) and seen[0].cfg.model.family == "toy"
  assert end_of_run.standard(tiny_config(*TOY)) == [end_of_run.end_sample]  # no calibration: nothing to choose
  summary = train_and_evaluate(tiny_config(*TOY), tmp_path / "w", finish=[hook])  # resumed at its end
  assert len(seen) == 2


def test_writing_a_sample_refuses_counts_that_are_no_whole_numbers_before_any_work(toy_run, tmp_path):
  for bad in ({"frames": "10"}, {"num": 1.5}, {"seed": -3}):
    with pytest.raises(chorjax.UserError, match="must be a whole number"):
      chorjax.api.write_sample(toy_run.workdir, tmp_path / "s.csv", **bad)
  assert not any(tmp_path.iterdir())


def test_the_patch_family_recombines_one_take_without_training(tmp_path, capsys):
  """``configs/patch.toml`` on a single take: one step keeps the take in the run; a dance of 600 frames is
  made of the take's own pieces (coverage of its windows, its pace), one per seed, from a run whose take is
  gone; what a patch run cannot do is one line."""
  import shutil

  from chorjax.data.dataset import bundled_path
  from chorjax.evaluation.scoring import score_motions

  take = tmp_path / "phrase.csv"
  shutil.copy(bundled_path("cmu94") / "94_03_skeleton_3d.csv", take)
  root = Path(__file__).resolve().parents[1]
  run = tmp_path / "run"
  argv = ["train", str(root / "configs" / "patch.toml"), f"data.dataset={take}", "log.tensorboard=false"]
  assert cli.main([*argv, "sample.frames=60", "--workdir", str(run)]) == 0
  take.unlink()  # the run keeps what it recombines
  a, b = (tmp_path / "a.csv"), (tmp_path / "b.csv")
  assert cli.main(["sample", str(run), "-o", str(a), "--frames", "600", "--seed", "1"]) == 0
  assert cli.main(["sample", str(run), "-o", str(b), "--frames", "600", "--seed", "2"]) == 0
  dance, other = chorjax.read_motion(a), chorjax.read_motion(b)
  assert dance.num_frames == 600 and not np.allclose(dance.positions, other.positions)
  real = chorjax.read_motion(bundled_path("cmu94") / "94_03_skeleton_3d.csv")
  scores = score_motions([dance], [real], window=60, splits=2, seed=0)
  assert scores["coverage"] > 0.3 and 0.7 < scores["speed"] < 1.3, scores
  capsys.readouterr()
  for command, said in (("calibrate", "no draw to calibrate"), ("live", "live mode streams"), ("export", "no network")):
    extra = ["-o", str(tmp_path / "d.onnx")] if command == "export" else []
    assert cli.main([command, str(run), *extra]) == 2 and said in capsys.readouterr().err
