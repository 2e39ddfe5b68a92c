"""Sampling (shapes, seeds, greedy, priming, back to data space), the sample/render CLI, GIF/MP4 files,
and the HTML player in headless Chromium."""

import json
import shutil
import subprocess
from pathlib import Path

import imageio.v3 as iio
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import nnx
from helpers import headless, tiny_config

from chorjax import cli
from chorjax.data.csv import read_csv, write_csv
from chorjax.data.dataset import bundled_path, load_dataset
from chorjax.data.npz import read_npz
from chorjax.families.recurrent import generation
from chorjax.families.recurrent.generation import generate
from chorjax.models import as_weights, parse_mix
from chorjax.run import load_run
from chorjax.sampling.controls import Bounds, Draw, Pacing
from chorjax.training.driver import train_and_evaluate

ROOT = Path(__file__).resolve().parents[1]
TAKE = bundled_path("cmu94") / "94_07_skeleton_3d.csv"


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
  w = tmp_path_factory.mktemp("run")
  train_and_evaluate(tiny_config("train.num_steps=3", "log.tensorboard=false", "sample.pi_temperature=0.3"), w)
  return w


@pytest.fixture(scope="module")
def loaded(run_dir):
  return load_run(run_dir)


def test_shapes_seeds_and_greedy(loaded):
  graphdef, params = loaded.graphdef, loaded.params
  w = jnp.tile(as_weights(jnp.array([3]), 10), (4, 1))
  gen = lambda seed, **kw: np.asarray(
    generate(graphdef, params, w, jax.random.key(seed), num_frames=50, draw=Draw(**kw))
  )
  a, b, c = gen(0), gen(0), gen(1)
  assert a.shape == (4, 50, 48) and np.isfinite(a).all()
  np.testing.assert_array_equal(a, b)
  assert not np.allclose(a, c)
  assert not np.allclose(a[0], a[1])  # the K dancers are independent draws
  g1, g2 = gen(0, greedy=True), gen(7, greedy=True)
  np.testing.assert_array_equal(g1, g2)


def test_the_unrolled_loop_draws_what_one_frame_per_iteration_draws(loaded):
  w = jnp.tile(as_weights(jnp.array([3]), 10), (4, 1))
  draw = lambda unroll: np.asarray(
    jax.jit(generation._generate.__wrapped__, static_argnames=("graphdef", "num_frames", "unroll"))(
      loaded.graphdef, loaded.params, w, jax.random.key(0), Draw(), num_frames=102, unroll=unroll
    )
  )
  unrolled = draw(generation.UNROLL)
  assert generation.UNROLL > 1
  np.testing.assert_allclose(unrolled, draw(1), rtol=0, atol=1e-5)  # 102 frames: not a multiple of 4
  assert not np.allclose(unrolled[:, :50], unrolled[:, 50:100])  # a dance, not a still pose


def test_long_generation_works(loaded):
  z = generate(loaded.graphdef, loaded.params, jnp.array([0]), jax.random.key(0), num_frames=10_000)
  assert z.shape == (1, 10_000, 48) and bool(jnp.isfinite(z).all())


def test_priming_reproduces_the_teacher_forced_states(loaded):
  graphdef, params = loaded.graphdef, loaded.params
  prime = jnp.asarray(loaded.features.encode(read_csv(TAKE).positions[:30]))[None]
  w = jnp.array([6])
  model = nnx.merge(graphdef, params)
  carry = model.initial_carry(w)
  for t in range(30):
    carry, _ = model.step(carry, prime[:, t])
  forced = model.teacher_force(prime, model.initial_carry(w))[1]
  for a, b in zip(jax.tree.leaves(carry), jax.tree.leaves(forced)):
    np.testing.assert_allclose(a, b, atol=1e-5)
  # and generation continues from that state: greedy continuation equals stepping on from it
  cont = generate(graphdef, params, w, jax.random.key(0), num_frames=3, prime_BxPxD=prime, draw=Draw(greedy=True))
  carry = model.initial_carry(w)
  for t in range(30):
    carry, out = model.step(carry, prime[:, t])
  np.testing.assert_allclose(cont[:, 0], model.sample(out, None, greedy=True), atol=1e-5)


class EchoModel(nnx.Module):
  """A model that predicts its own input: its free-running sample must be the primed frame, held."""

  def __init__(self, dim):
    self.dim = dim
    self.unused = nnx.Param(jnp.zeros(()))

  def initial_carry(self, motion):
    return (jnp.zeros((motion.shape[0], 1)),)

  def teacher_force(self, x, carry):
    return x, carry

  def step(self, carry, x):
    return carry, x

  def sample(self, out, key, *a):
    return out


def test_samples_come_back_in_data_units_and_axes(run_dir):
  ds = load_dataset(tiny_config().data)
  graphdef, params = nnx.split(EchoModel(48), nnx.Param)
  take = read_csv(TAKE).positions
  prime = jnp.asarray(ds.features.encode(take[100:110]))[None]
  z = generate(graphdef, nnx.to_pure_dict(params), jnp.array([0]), jax.random.key(0), num_frames=5, prime_BxPxD=prime)
  pos = np.asarray(ds.features.decode(z))[0]
  np.testing.assert_allclose(pos, np.broadcast_to(take[109], pos.shape), rtol=1e-4, atol=1e-3)


def test_mix_parsing():
  np.testing.assert_allclose(parse_mix("4:0.5,5:0.5", 10), np.eye(10)[4] * 0.5 + np.eye(10)[5] * 0.5)
  from chorjax.errors import UserError

  with pytest.raises(UserError, match="out of range"):
    parse_mix("12:1", 10)


def test_sample_cli_writes_csv_npz_with_blends_and_primes(run_dir, tmp_path, capsys):
  out = tmp_path / "s.csv"
  assert cli.main(["sample", str(run_dir), "-o", str(out), "--frames", "40", "--mix", "4:0.5,5:0.5"]) == 0
  m = read_csv(out)
  assert m.positions.shape == (40, 16, 3)
  # data units: the sample's mean bone length is on the scale of the takes' (~54 units), not normalized
  assert 20 < m.bone_lengths().mean() < 200
  assert cli.main(["sample", str(run_dir), "-o", str(out), "--frames", "5"]) == 2  # no silent overwrite
  assert "already exists" in capsys.readouterr().err
  npz = tmp_path / "s.npz"
  assert (
    cli.main(
      [
        "sample",
        str(run_dir),
        "-o",
        str(npz),
        "--frames",
        "20",
        "--num",
        "3",
        "--prime",
        f"{TAKE}:100:10",
        "--set",
        "sample.greedy=true",
        "--checkpoint",
        "3",
      ]
    )
    == 0
  )
  ms = read_npz(npz)
  assert len(ms) == 3 and ms[0].positions.shape == (10 + 20, 16, 3)
  np.testing.assert_allclose(ms[0].positions[:10], read_csv(TAKE).positions[100:110], rtol=1e-4, atol=1e-2)
  with np.load(npz) as z:
    settings = json.loads(str(z["meta"]))["settings"]
  assert settings["greedy"] is True
  assert settings["pi_temperature"] == 0.3 and settings["sigma_temperature"] == 1.0  # the run's [sample] defaults


def test_render_gif_and_mp4_are_valid_720p_side_by_side_and_fork_free(tmp_path, recwarn):
  gif, mp4 = tmp_path / "a.gif", tmp_path / "a.mp4"
  assert cli.main(["render", str(TAKE), "-o", str(gif), "--frames", "12", "--size", "480x360"]) == 0
  frames = iio.imread(gif, index=None)
  assert frames.shape[0] == 12 and frames.shape[1:3] == (360, 480)
  other = bundled_path("cmu94") / "94_01_skeleton_3d.csv"
  assert cli.main(["render", str(TAKE), str(other), "-o", str(mp4), "--frames", "12"]) == 0
  assert not [w for w in recwarn if "fork" in str(w.message)]  # no deadlock warning from the ffmpeg subprocess
  import imageio_ffmpeg

  reader = imageio_ffmpeg.read_frames(str(mp4))
  meta = next(reader)
  assert tuple(meta["size"]) == (1280, 720) and meta["fps"] == pytest.approx(30)  # 720p by default
  first = np.frombuffer(next(reader), np.uint8).reshape(720, 1280, 3)
  assert sum(1 for _ in reader) == 11
  ink = (first.min(-1) < 150).any(0)  # columns holding a dark stroke: a dancer in each half
  assert ink[:640].sum() > 40 and ink[640:].sum() > 40
  rows = np.flatnonzero((first.min(-1) < 150).any(1))
  assert rows.max() - rows.min() > 0.4 * 720  # the figure fills the frame's height, not a corner
  assert cli.main(["render", str(TAKE), "-o", str(tmp_path / "b.mp4"), "--size", "12"]) == 2
  png = tmp_path / "a.png"
  assert cli.main(["render", str(TAKE), "-o", str(png)]) == 0 and png.read_bytes()[:4] == b"\x89PNG"


def test_strip_rows_are_start_middle_and_end_and_render_strip_draws_them(tmp_path, capsys):
  from chorjax.render.plot import strip_rows

  assert strip_rows(10_000, 6, 12) == [("start", 0), ("middle", 4966), ("end", 9933)]
  assert strip_rows(100, 6, 12) == [("start", 0), ("end", 33)]  # a middle row would overlap both
  assert strip_rows(50, 6, 12) == [("whole", 0)]
  png = tmp_path / "strip.png"
  assert cli.main(["render", str(TAKE), "-o", str(png), "--strip", "--every", "4", "--poses", "8"]) == 0
  image = iio.imread(png)
  assert image.shape[:2] == (round(3 * 1.9 * 80), round(8 * 0.9 * 80))  # three rows of eight poses at dpi 80
  ink = (image[..., :3] < 200).any(-1)  # drawn pixels in each row's band
  assert all(ink[r * 152 : (r + 1) * 152].sum() > 500 for r in range(3))
  assert cli.main(["render", str(TAKE), "-o", str(tmp_path / "s.gif"), "--strip"]) == 2
  assert "--strip draws a PNG" in capsys.readouterr().err


def chromium():
  for name in ("chromium-headless-shell", "chromium"):
    path = shutil.which(name)
    if path:
      return path
  pytest.fail("headless Chromium is missing: .ci/run installs Debian's chromium-headless-shell")


def test_html_player_in_headless_chromium(run_dir, tmp_path):
  html = tmp_path / "player.html"
  takes = [str(TAKE), str(bundled_path("cmu94") / "94_01_skeleton_3d.csv"), str(run_dir / "samples" / "sample.csv")]
  assert cli.main(["render", *takes, "-o", str(html)]) == 0
  text = html.read_text()
  assert "http://" not in text and "https://" not in text and "<script src" not in text  # offline
  flags = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    f"--user-data-dir={tmp_path / 'profile'}",
  ]
  # the end-of-training player (original beside generated) and a render of three, on two screens
  for page, panels in ((run_dir / "samples" / "player.html", 2), (html, 3)):
    for width, height in ((1280, 800), (1920, 1080)):
      dom = subprocess.run(
        [
          chromium(),
          *flags,
          f"--window-size={width},{height}",
          "--virtual-time-budget=3000",
          "--dump-dom",
          f"file://{page}#selftest",
        ],
        capture_output=True,
        text=True,
        timeout=120,
      ).stdout
      report = json.loads(dom.split('<pre id="selftest">')[1].split("</pre>")[0])
      assert report["errors"] == []
      assert report["nonblank"] > 1000  # stick figures and floor were drawn
      assert report["changed"] and report["frames"][1] > report["frames"][0]  # it plays by itself
      w, h = report["viewport"]
      boxes = report["boxes"]
      assert len(boxes) == panels
      for left, top, right, bottom in boxes:  # every dancer fully visible without scrolling
        assert 0 <= left < right <= w and 0 <= top < bottom <= h and bottom - top > 0.4 * h
      assert len({round(top) for _, top, _, _ in boxes}) == 1  # side by side, one row
      for (px, py), (left, top, right, bottom) in zip(report["pixels"], boxes):
        assert px >= right - left - 1 and py >= bottom - top - 1  # canvas pixels match the box: crisp
  artifacts = ROOT / "test-artifacts"
  artifacts.mkdir(exist_ok=True)
  shot = artifacts / "player.png"
  subprocess.run(
    [
      chromium(),
      *flags,
      "--window-size=1280,800",
      f"--screenshot={shot}",
      f"file://{run_dir / 'samples' / 'player.html'}",
    ],
    capture_output=True,
    timeout=120,
  )
  assert shot.read_bytes()[:4] == b"\x89PNG"


def test_several_dancers_never_overwrite_their_files(run_dir, tmp_path, capsys):
  (tmp_path / "s_1.csv").write_text("mine")
  assert cli.main(["sample", str(run_dir), "-o", str(tmp_path / "s.csv"), "--frames", "5", "--num", "2"]) == 2
  assert "s_1.csv: already exists" in capsys.readouterr().err
  assert (tmp_path / "s_1.csv").read_text() == "mine" and not (tmp_path / "s_0.csv").exists()


def test_prime_from_another_format_is_read_as_training_reads(run_dir, tmp_path, shared_data):
  from chorjax.config import config_from_dict
  from chorjax.data.bvh import read_bvh
  from chorjax.data.dataset import conform

  bvh = shared_data / "bvh" / "cmu131" / "131_01.bvh"  # y-up, 38 joints: mapped and rotated like a take
  assert (
    cli.main(["sample", str(run_dir), "-o", str(tmp_path / "p.csv"), "--frames", "5", "--prime", f"{bvh}:100:10"]) == 0
  )
  data_cfg = config_from_dict(json.loads((run_dir / "config.json").read_text())).data
  want = conform([read_bvh(bvh)], data_cfg)[0].positions[100:110]
  got = read_csv(tmp_path / "p.csv").positions[:10]
  np.testing.assert_allclose(got, want, atol=1e-3 * np.ptp(want[..., 1]))


def test_an_impossible_end_sample_fails_before_training(tmp_path, capsys):
  from chorjax.config import to_toml

  cfg = tmp_path / "c.toml"
  cfg.write_text(to_toml(tiny_config("sample.motion=12")))
  assert cli.main(["train", str(cfg), "--workdir", str(tmp_path / "w")]) == 2
  assert "sample.motion = 12: out of range (0..9)" in capsys.readouterr().err
  assert not (tmp_path / "w" / "checkpoints").exists()


def test_sample_and_eval_print_nothing_on_stderr_for_a_good_run(run_dir, tmp_path):
  import sys

  cmd = [sys.executable, "-m", "chorjax.cli"]
  out = tmp_path / "quiet.csv"
  r = subprocess.run([*cmd, "sample", str(run_dir), "-o", str(out), "--frames", "10"], capture_output=True, text=True)
  assert r.returncode == 0 and r.stderr == "" and out.exists()
  args = ["--data", "cmu94/94_10_skeleton_3d.csv", "--frames", "120", "--num", "1", "--splits", "2"]
  r = subprocess.run(
    [*cmd, "eval", str(run_dir), *args[:-2], "-o", str(tmp_path / "m.json")], capture_output=True, text=True
  )
  assert r.returncode == 0 and r.stderr == "", r.stderr[-500:]


def test_smooth_noise_has_unit_variance_and_is_smooth_and_white_at_zero():
  from chorjax.families.recurrent.generation import MAX_NOISE_ORDER, smooth_noise

  def draw(rho, order=2, n=4000):
    step = lambda s, k: smooth_noise(s, k, rho, order)
    _, out = jax.lax.scan(step, jnp.zeros((MAX_NOISE_ORDER, 256)), jax.random.split(jax.random.key(0), n))
    return np.asarray(out)[500:]  # past the start from rest

  smooth, white = draw(0.9), draw(0.0)
  assert 0.9 < smooth.var() < 1.1 and 0.95 < white.var() < 1.05
  lag1 = lambda e: np.mean(e[1:] * e[:-1]) / e.var()
  assert lag1(smooth) > 0.95 and abs(lag1(white)) < 0.02
  rough = lambda e: np.mean(np.abs(e[2:] - 2 * e[1:-1] + e[:-2]))
  assert rough(smooth) < 0.1 * rough(white)  # what the eye calls trembling
  # four filters at 0.8 move about as far per frame as two at 0.9, with a third of the tremble
  fourth = draw(0.8, order=4)
  assert 0.9 < fourth.var() < 1.1 and 0.9 < draw(0.5, order=1).var() < 1.1
  speed = lambda e: np.mean(np.abs(np.diff(e, axis=0)))
  assert 0.8 < speed(fourth) / speed(smooth) < 1.2
  assert rough(fourth) < 0.45 * rough(smooth)


def test_persistence_and_smoothing_keep_the_default_path_and_make_a_smoother_dance(loaded):
  graphdef, params = loaded.graphdef, loaded.params
  w = jnp.tile(as_weights(jnp.array([3]), 10), (4, 1))
  gen = lambda **kw: np.asarray(generate(graphdef, params, w, jax.random.key(0), num_frames=300, draw=Draw(**kw)))
  plain = gen(pi_temperature=1.0, sigma_temperature=1.0)
  np.testing.assert_array_equal(plain, gen(pi_temperature=1.0, sigma_temperature=1.0, noise_smoothing=0.0))
  smooth = gen(pi_temperature=1.0, sigma_temperature=1.0, noise_smoothing=0.9, persistence=4.0)
  assert smooth.shape == plain.shape and np.isfinite(smooth).all()
  np.testing.assert_array_equal(
    smooth, gen(pi_temperature=1.0, sigma_temperature=1.0, noise_smoothing=0.9, persistence=4.0)
  )
  rough = lambda z: np.mean(np.abs(z[:, 2:] - 2 * z[:, 1:-1] + z[:, :-2]))
  assert rough(smooth) < 0.5 * rough(plain)
  # a change of component glides instead of cutting: the largest frame-to-frame jump shrinks
  hop = {"pi_temperature": 1.0, "sigma_temperature": 0.0, "noise_smoothing": 0.5}  # no noise: jumps are switches
  cut, glide = gen(**hop), gen(**hop, crossfade=0.8)
  jump = lambda z: np.abs(np.diff(z, axis=1)).max(axis=(1, 2))
  assert np.mean(jump(glide)) < 0.7 * np.mean(jump(cut))


def test_sample_cli_smoothing_persistence_and_rigid_bones(run_dir, tmp_path, capsys):
  from chorjax.data.motion import bone_length_cv

  out = tmp_path / "s.npz"
  flags = [
    "--frames",
    "200",
    "--set",
    "sample.noise_smoothing=0.9",
    "--set",
    "sample.persistence=4",
    "--set",
    "sample.pi_temperature=1",
  ]
  assert cli.main(["sample", str(run_dir), "-o", str(out), *flags, "--rigid-bones"]) == 0
  m = read_npz(out)[0]
  assert bone_length_cv(m.positions, m.skeleton).max() < 1e-4
  assert json.loads(str(np.load(out)["meta"]))["settings"]["noise_smoothing"] == 0.9
  loose = tmp_path / "loose.npz"
  assert cli.main(["sample", str(run_dir), "-o", str(loose), *flags]) == 0
  assert bone_length_cv(read_npz(loose)[0].positions, m.skeleton).max() > 1e-3
  for bad in (
    ["--set", "sample.noise_smoothing=1"],
    ["--set", "sample.persistence=-1"],
    ["--set", "sample.pi_temperature=nan"],
  ):
    assert cli.main(["sample", str(run_dir), "-o", str(tmp_path / "bad.csv"), *bad]) == 2
    assert capsys.readouterr().err.count("\n") == 1
  assert not (tmp_path / "bad.csv").exists()


def test_clamp_keeps_every_frame_in_the_training_range(loaded, run_dir, tmp_path, capsys):
  import dataclasses

  from chorjax.errors import UserError
  from chorjax.families.recurrent.generation import dance

  f = loaded.features
  every = np.concatenate([x for _, x in load_dataset(loaded.config.data).train])  # what training windows show
  np.testing.assert_array_equal(f.low, every.min(0))
  np.testing.assert_array_equal(f.high, every.max(0))
  w = jnp.tile(as_weights(jnp.array([3]), 10), (4, 1))
  wide = {"pi_temperature": 1.0, "sigma_temperature": 3.0, "noise_smoothing": 0.5}
  gen = lambda **kw: np.asarray(
    generate(loaded.graphdef, loaded.params, w, jax.random.key(0), num_frames=200, draw=Draw(**kw))
  )
  free, held = gen(**wide), gen(**wide, bounds=Bounds(f.low, f.high))
  assert ((free < f.low) | (free > f.high)).any()  # a wide draw leaves the range ...
  assert ((held >= f.low) & (held <= f.high)).all()  # ... the clamped one never does
  assert np.isfinite(held).all() and not np.allclose(held[0], held[1])
  # a run trained before the range was recorded gets it from its own training data ...
  old = dataclasses.replace(loaded, features=dataclasses.replace(f, **dict.fromkeys(f.RANGES)))
  assert old.ranged(old.sampling(clamp=False)) is old
  np.testing.assert_array_equal(old.ranged(old.sampling(clamp=True)).features.low, f.low)
  with pytest.raises(UserError, match=r"needs a training range or pace .*changed"):  # ... unless that data changed
    dataclasses.replace(old, features=dataclasses.replace(old.features, mean=old.features.mean + 1)).ranged(
      old.sampling(clamp=True)
    )
  controls = loaded.sampling(clamp=True)
  with pytest.raises(UserError, match="no training range"):
    dance(old.graphdef, old.params, old.features, np.array([0]), jax.random.key(0), 10, controls)
  out = tmp_path / "c.npz"
  assert cli.main(["sample", str(run_dir), "-o", str(out), "--frames", "100", "--clamp"]) == 0
  assert json.loads(str(np.load(out)["meta"]))["settings"]["clamp"] is True


def test_clamp_steps_holds_every_change_to_the_training_changes(loaded, run_dir, tmp_path):
  import dataclasses

  f = loaded.features
  train = [x for _, x in load_dataset(loaded.config.data).train]
  steps = np.concatenate([np.diff(x, axis=0) for x in train])
  np.testing.assert_array_equal(f.step_low, steps.min(0))
  np.testing.assert_array_equal(f.step_high, steps.max(0))
  w = jnp.tile(as_weights(jnp.array([3]), 10), (4, 1))
  wide = {"pi_temperature": 1.0, "sigma_temperature": 3.0, "noise_smoothing": 0.5}
  gen = lambda **kw: np.asarray(
    generate(loaded.graphdef, loaded.params, w, jax.random.key(0), num_frames=200, draw=Draw(**kw))
  )
  controls = loaded.sampling(clamp=True, clamp_steps=True)
  bounds = controls.draw(f).bounds
  assert bounds is not None and bounds.step_low is not None
  free, held = gen(**wide, bounds=Bounds(bounds.low, bounds.high)), gen(**wide, bounds=bounds)
  change = lambda z: np.diff(z, axis=1)
  tol = 1e-5
  assert ((change(free) < f.step_low - tol) | (change(free) > f.step_high + tol)).any()  # a wide draw jumps ...
  assert ((change(held) >= f.step_low - tol) & (change(held) <= f.step_high + tol)).all()  # ... a held one never
  assert ((held >= f.low) & (held <= f.high)).all() and np.abs(change(held)).mean() > 0  # in range, still moving
  # a run that records no steps measures them on its training takes
  old = dataclasses.replace(loaded, features=dataclasses.replace(f, **dict.fromkeys(f.STEPS)))
  np.testing.assert_array_equal(old.ranged(old.sampling(clamp_steps=True)).features.step_high, f.step_high)
  out = tmp_path / "s.npz"
  assert cli.main(["sample", str(run_dir), "-o", str(out), "--frames", "100", "--set", "sample.clamp_steps=true"]) == 0
  assert json.loads(str(np.load(out)["meta"]))["settings"]["clamp_steps"] is True


def test_pace_governor_drives_the_dancer_towards_the_training_pace(loaded, run_dir, tmp_path):
  f = loaded.features
  lag = f.pace_lag
  train = [x for _, x in load_dataset(loaded.config.data).train]
  assert lag == round(0.5 * loaded.fps)
  pose = f.pose_channels
  assert f.pace == pytest.approx(
    np.concatenate([np.abs(x[lag:, pose] - x[:-lag, pose]).mean(-1) for x in train]).mean()
  )
  w = jnp.tile(as_weights(jnp.array([3]), 10), (4, 1))
  base = {"pi_temperature": 1.0, "sigma_temperature": 1.0, "noise_smoothing": 0.5, "pace_lag": lag}
  weights = np.zeros(f.dim, np.float32)
  weights[pose] = 1 / len(pose)
  gen = lambda **kw: np.asarray(
    generate(loaded.graphdef, loaded.params, w, jax.random.key(0), num_frames=400, draw=Draw(**kw))
  )
  pace_of = lambda z: np.abs(z[:, 200 + lag :, pose] - z[:, 200:-lag, pose]).mean()  # once the running mean settled
  free = gen(**base)
  held = lambda ref: gen(**base, pace=2.0, pacing=Pacing(ref, weights=weights))
  slow, fast = held(0.5 * pace_of(free)), held(2 * pace_of(free))
  assert pace_of(slow) < 0.9 * pace_of(free) < 0.9 * pace_of(fast)  # held back, left alone, pushed on
  assert np.isfinite(fast).all()
  out = tmp_path / "p.npz"
  assert cli.main(["sample", str(run_dir), "-o", str(out), "--frames", "100", "--pace", "1"]) == 0
  assert json.loads(str(np.load(out)["meta"]))["settings"]["pace"] == 1.0


def test_off_pace_the_governor_changes_the_scale_and_lets_go_of_the_component():
  from chorjax.families.recurrent.generation import _governed

  controls = {"sigma_temperature": 1.2, "persistence": 6.0, "crossfade": 0.8}
  own = jnp.array([1.0, 0.5, 2.0, 0.01])  # on pace, calm, racing, nearly still (training pace 1)
  g = _governed(controls, own, 1.0, 2.0)
  np.testing.assert_allclose(g["sigma_temperature"][:, 0], [1.2, 2.4, 0.6, 2.4])  # x (1 / own)^2 within 0.5-2
  np.testing.assert_allclose(g["persistence"][:, 0], [6.0, 1.5, 1.5, 1.5])  # either way off pace: let go
  assert g["crossfade"] == 0.8


def test_scale_cap_holds_draws_to_the_scales_the_model_predicts_on_its_data(loaded, run_dir, tmp_path, capsys):
  from chorjax.errors import UserError
  from chorjax.families.recurrent.generation import dance
  from chorjax.models.heads import MDNHead
  from chorjax.sampling.controls import scale_ceiling

  train = load_dataset(loaded.config.data).train
  seq = loaded.config.data.seq_length
  low, high = (scale_ceiling(loaded.graphdef, loaded.params, train, seq, q) for q in (0.5, 0.99))
  assert low.shape == high.shape == (loaded.features.dim,) and (low > 0).all() and (high >= low).all()
  model = nnx.merge(loaded.graphdef, loaded.params)
  assert isinstance(model.head, MDNHead) and (high >= model.head.min_scale).all()
  w = jnp.tile(as_weights(jnp.array([3]), 10), (4, 1))
  base = {"pi_temperature": 1.0, "sigma_temperature": 1.0, "noise_smoothing": 0.5}
  gen = lambda **kw: np.asarray(
    generate(loaded.graphdef, loaded.params, w, jax.random.key(0), num_frames=300, draw=Draw(**kw))
  )
  free = gen(**base)
  np.testing.assert_array_equal(gen(**base, scale_cap=np.full(low.shape, np.inf, np.float32)), free)  # no cap: same
  tight = gen(**base, scale_cap=np.full(low.shape, 1e-3, np.float32))  # draws at the component means
  step = lambda z: np.abs(np.diff(z, axis=1)).mean()
  assert step(tight) < 0.5 * step(free) and np.isfinite(tight).all()
  # through the run: measured from its training data when asked for, recorded in the sample's settings
  controls = loaded.sampling(scale_cap=0.9)
  with pytest.raises(UserError, match="scale ceiling was not measured"):
    dance(loaded.graphdef, loaded.params, loaded.features, np.array([0]), jax.random.key(0), 10, controls)
  ceiled = loaded.ranged(controls).features.scale_ceiling
  np.testing.assert_allclose(ceiled, scale_ceiling(loaded.graphdef, loaded.params, train, seq, 0.9))
  out = tmp_path / "s.npz"
  assert cli.main(["sample", str(run_dir), "-o", str(out), "--frames", "100", "--set", "sample.scale_cap=0.95"]) == 0
  assert json.loads(str(np.load(out)["meta"]))["settings"]["scale_cap"] == 0.95
  assert cli.main(["sample", str(run_dir), "-o", str(tmp_path / "t.npz"), "--set", "sample.scale_cap=1.5"]) == 2
  assert "scale_cap" in capsys.readouterr().err


@pytest.mark.parametrize("flag", ["--foot-lock", "--ground"])
def test_foot_lock_and_ground_need_the_canonical_representation(run_dir, tmp_path, capsys, flag):
  assert cli.main(["sample", str(run_dir), "-o", str(tmp_path / "s.csv"), flag]) == 2
  err = capsys.readouterr().err
  assert err.count("\n") == 1 and "canonical" in err and not (tmp_path / "s.csv").exists()


@pytest.mark.parametrize(
  "command",
  [
    "sample RUN -o OUT.csv --frames 0",
    "sample RUN -o OUT.csv --frames -5",
    "sample RUN -o OUT.csv --num 0",
    "sample RUN -o OUT.csv --num -2",
    "sample RUN -o OUT.csv --mix 4:-1,5:2",
    "sample RUN -o OUT.csv --mix 4:nan",
    "sample RUN -o OUT.csv --set sample.pi_temperature=-1",
    "sample RUN -o OUT.csv --sigma-temperature inf",
    "eval RUN --data cmu94 -o OUT.json --num 0",
    "eval RUN --data cmu94 -o OUT.json --frames 1",
    "render TAKE -o OUT.png --frames 0",
    "render TAKE -o OUT.png --strip --every 0",
    "render TAKE -o OUT.mp4 --size 100",
  ],
)
def test_impossible_counts_and_weights_are_one_line_errors(run_dir, tmp_path, capsys, command):
  out = tmp_path / "out"
  args = command.replace("RUN", str(run_dir)).replace("TAKE", str(TAKE)).replace("OUT", str(out)).split()
  before = sorted(p.name for p in run_dir.rglob("*"))
  assert cli.main(args) == 2
  err = capsys.readouterr().err
  assert err.count("\n") == 1 and err.startswith("chorjax: error: --"), err
  assert not list(tmp_path.iterdir()) and sorted(p.name for p in run_dir.rglob("*")) == before


def test_hostile_take_names_and_titles_run_no_script_in_the_player(tmp_path):
  """A take named like markup and a title holding the data placeholder: the page shows them as text, no
  script of theirs runs (their own would push to window.__errors), and the dancers still play."""
  hostile = ["<img src=x onerror=window.__errors.push('pwned-img')>", "a<!--<script>b"]
  takes = []
  for k, name in enumerate(hostile):
    path = tmp_path / f"{name}.csv"
    path.write_bytes((bundled_path("cmu94") / f"94_0{k + 1}_skeleton_3d.csv").read_bytes())
    takes.append(str(path))
  html = tmp_path / "player.html"
  title = "__DATA__ </title><script>window.__errors.push('pwned-title')</script>"
  assert cli.main(["render", *takes, "-o", str(html), "--title", title]) == 0
  text = html.read_text()
  assert "<img src=x" not in text and "<script>window.__errors.push('pwned" not in text and "<!--<script>b" not in text
  dom = headless(tmp_path / "profile", f"file://{html}#selftest", "--virtual-time-budget=3000", "--dump-dom").stdout
  report = json.loads(dom.split('<pre id="selftest">')[1].split("</pre>")[0])
  assert report["errors"] == []  # nothing of the names or the title ran (nor broke the page's script)
  assert report["changed"] and report["frames"][1] > report["frames"][0] and len(report["boxes"]) == 2
  assert "&lt;img src=x onerror" in dom and "<img src=" not in dom  # the name shown as text in its caption
  assert dom.count("__DATA__") == 2  # the title, as text (in <title> and the heading)


def test_the_players_camera_follows_a_dancer_who_travels(tmp_path):
  """A dancer who travels ten body heights away (as a free-running sample can) stays on the player's canvas:
  the camera follows it. With the camera fixed at the take's centre, the figure left the canvas."""
  from helpers import headless

  take = read_csv(TAKE)
  pos = take.positions.copy()
  height = float(np.ptp(pos[..., 1]))
  pos[..., 0] += np.linspace(0, 10 * height, len(pos))[:, None]  # walks off along x
  path = tmp_path / "travels.csv"
  write_csv(take.replace(positions=pos), path)
  html = tmp_path / "player.html"
  assert cli.main(["render", str(path), "-o", str(html)]) == 0
  for frame in (0, len(pos) - 40):
    dom = headless(tmp_path / "profile", f"file://{html}#selftest@{frame}", "--virtual-time-budget=3000", "--dump-dom")
    report = json.loads(dom.stdout.split('<pre id="selftest">')[1].split("</pre>")[0])
    assert report["errors"] == [] and report["inside"] == [1.0], (frame, report)
