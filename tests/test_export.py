"""`chorjax export`: the dancer as an ONNX graph that onnxruntime runs frame by frame, drawing what `chorjax
sample` draws given the same random numbers."""

import json
from pathlib import Path

import jax
import numpy as np
import onnx
import pytest
from helpers import BLENDER_PYTHON, GAN_NETWORKS, QUICKSTART_SAMPLING, TINY

from chorjax import cli
from chorjax.api import load_run
from chorjax.config import load_config
from chorjax.data.csv import read_csv
from chorjax.data.dataset import bundled_path
from chorjax.data.features import Features
from chorjax.errors import UserError
from chorjax.export.dancer import OnnxDancer, sample_numbers
from chorjax.models import motion_weight_vector
from chorjax.sample import sample_dancers
from chorjax.training.driver import train_and_evaluate

ROOT = Path(__file__).resolve().parents[1]
NODE_MODULES = ROOT / ".venv" / "node"  # .ci/run: npm install --prefix .venv/node gltf-validator onnxruntime-web


def trained(where: Path, *overrides: str, config: Path | None = None) -> Path:
  cfg = load_config(config, [*TINY, "train.calibrate=false", "log.tensorboard=false", *overrides])
  train_and_evaluate(cfg, where)
  return where


@pytest.fixture(scope="module")
def quickstart(tmp_path_factory):
  """A tiny run of the shipped quick-start recipe (an MDN carrying its noise over 3 frames; its draw: the scale
  temperature, the pace governor, the training range; rigid bones, ground, foot lock)."""
  where = tmp_path_factory.mktemp("export") / "run"
  return trained(where, "train.num_steps=4", config=ROOT / "configs" / "quickstart.toml")


@pytest.fixture(scope="module")
def white(tmp_path_factory):
  """A tiny run of configs/white.toml (a white-noise MDN; its draw: smoothed noise of order 4, persistence,
  crossfade, the training range and steps, the pace governor, the scale ceiling)."""
  where = tmp_path_factory.mktemp("export_white") / "run"
  return trained(where, "train.num_steps=4", config=ROOT / "configs" / "white.toml")


# what each was exported with
EXPORTED = {"quickstart": {"noise_order": 1, "pace": 2.0, "persistence": 0.0}, "white": {"noise_order": 4, "pace": 2.0}}


def body_size(pos) -> float:
  return float(np.ptp(pos.reshape(-1, 3), axis=0).max())


@pytest.mark.parametrize("recipe", EXPORTED)
def test_the_onnx_dancer_draws_what_chorjax_sample_draws(recipe, request, tmp_path):
  """600 frames from onnxruntime, fed the random numbers `chorjax sample --seed 3` draws, are its frames within
  1e-4 of the body size on every joint of every frame: the quickstart's run, and a white-noise MDN's whose draw
  filters its noise and holds its components."""
  quickstart = request.getfixturevalue(recipe)
  dancer_path = tmp_path / "dancer.onnx"
  assert cli.main(["export", str(quickstart), "-o", str(dancer_path)]) == 0
  run = load_run(quickstart)
  dancer = OnnxDancer(dancer_path)
  meta = dancer.meta
  assert (meta["num_mixtures"], meta["dim"], meta["batch"]) == (3, run.features.dim, 1)
  assert EXPORTED[recipe].items() <= meta["controls"].items()

  frames, seed = 600, 3
  gumbel, normal = sample_numbers(run, seed, frames)
  z, joints = dancer.dance(motion_weight_vector(run.num_motions, 2)[None], gumbel, normal, joints=True)
  expected, _ = sample_dancers(run, frames, 1, seed, motion=2)
  got = dancer.positions(z)
  assert got.shape == expected.shape == (1, frames, run.features.skeleton.num_joints, 3)
  assert np.abs(got - expected).max() <= 1e-4 * body_size(expected)
  assert np.abs(np.diff(got, axis=1)).max() > 0  # it dances
  # the graph's own joints: the same frames decoded with rigid bones, not grounded or locked (that is the host's)
  assert meta["decoding"] == {"rigid": True, "lock_feet": True, "ground": True}
  rigid = Features.from_dict(meta["features"]).decode(z, rigid=True)
  assert joints.shape == got.shape and np.abs(joints - rigid).max() <= 1e-4 * body_size(rigid)


def test_the_graph_and_sidecar_state_the_contract(quickstart, tmp_path):
  assert cli.main(["export", str(quickstart), "-o", str(tmp_path / "d.onnx"), "--batch", "3"]) == 0
  model = onnx.load(tmp_path / "d.onnx")
  onnx.checker.check_model(model, full_check=True)
  meta = json.loads((tmp_path / "d.json").read_text())
  names = [i.name for i in model.graph.input]
  assert names == [io["name"] for io in meta["inputs"]]
  assert names[:4] == ["weights", "start", "gumbel", "normal"]
  assert [o.name for o in model.graph.output] == [io["name"] for io in meta["outputs"]]
  assert all(s["input"] in names for s in meta["state"]) and len(meta["state"]) == len(names) - 4
  for io in meta["inputs"]:  # every dancer its own, but the governor's ring position (one number)
    axis = 1 if io["name"] in ("state.filters", "state.governor.0") else 0
    assert io["shape"][axis] == 3 if io["name"] != "state.governor.1" else io["shape"] == []
  run = load_run(quickstart)
  sk = run.features.skeleton
  assert meta["skeleton"]["joint_names"] == list(sk.joint_names) and meta["skeleton"]["parents"] == list(sk.parents)
  assert len(meta["skeleton"]["bone_lengths"]) == sk.num_joints and meta["fps"] == run.fps
  assert meta["motions"] == run.id_map and meta["features"]["mean"] == np.asarray(run.features.mean).tolist()


def test_a_batch_of_dancers_each_on_its_own_motion_and_a_restart_mid_dance(quickstart, tmp_path):
  """Two dancers a call, one on a take and one on a blend, are the frame-by-frame draw of both at once; a
  dancer started over mid-dance (start = 1) dances as a fresh one from there, the other one going on."""
  run = load_run(quickstart)
  for bad in (0, 2.5, True):
    with pytest.raises(UserError, match="--batch"):
      run.export(tmp_path / "two.onnx", batch=bad)
  run.export(tmp_path / "two.onnx", batch=2)
  dancer = OnnxDancer(tmp_path / "two.onnx")
  m = run.num_motions
  weights = np.stack([motion_weight_vector(m, 1), motion_weight_vector(m, mix="0:0.5,3:0.5")])
  frames = 200
  gumbel, normal = sample_numbers(run, 5, frames, batch=2)
  z = dancer.dance(weights, gumbel, normal)
  sampling = run.sampling()
  ranged = run.ranged(sampling)
  key = jax.random.key(5)
  expected = ranged.family.dance(ranged.graphdef, ranged.params, ranged.features, weights, key, frames, sampling)
  got = dancer.positions(z)
  assert np.abs(got - expected).max() <= 1e-4 * body_size(expected)

  half = 80
  dancer.start(weights)
  for t in range(half):
    dancer.step(gumbel[t], normal[t])
  dancer.starting = np.array([0.0, 1.0], np.float32)  # the second dancer starts over
  rest, rest_joints = [], []
  for g, n in zip(gumbel[half:], normal[half:], strict=True):
    rest.append(dancer.step(g, n))
    rest_joints.append(dancer.joints)
  rest, rest_joints = np.stack(rest, 1), np.stack(rest_joints, 1)
  fresh, fresh_joints = dancer.dance(weights, gumbel[half:], normal[half:], joints=True)
  np.testing.assert_allclose(rest[0], z[0, half:], atol=1e-6)  # the first dancer went on
  np.testing.assert_allclose(rest[1], fresh[1], atol=1e-6)  # the second danced anew, from the origin
  np.testing.assert_allclose(rest_joints[1], fresh_joints[1], atol=1e-4 * body_size(fresh_joints))


@pytest.mark.parametrize(
  "cell,head,every_frame,memory",
  [("lnlstm", "mdn", False, 0), ("gru", "mse", True, 0), ("lstm", "mdn", False, 3)],
)
def test_other_cells_and_heads_export_with_the_same_draw(cell, head, every_frame, memory, tmp_path):
  """The LN-LSTM and the GRU, the MSE head, the plain draw (white noise, nothing held), the motion weights
  beside every frame's input (``model.condition_every_frame``: they ride in the graph's state), and an MDN
  that carries three residuals (``model.mdn_memory``: they ride in the state)."""
  run_dir = trained(
    tmp_path / "run",
    f"model.cell={cell}",
    f"model.head={head}",
    f"model.condition_every_frame={str(every_frame).lower()}",
    f"model.mdn_memory={memory}",
  )
  assert cli.main(["export", str(run_dir), "-o", str(tmp_path / "d.onnx"), "--set", "sample.noise_smoothing=0.5"]) == 0
  dancer = OnnxDancer(tmp_path / "d.onnx")
  run = load_run(run_dir)
  frames = 120
  gumbel, normal = sample_numbers(run, 1, frames)
  z, joints = dancer.dance(motion_weight_vector(run.num_motions)[None], gumbel, normal, joints=True)
  expected, _ = sample_dancers(run, frames, 1, 1, controls={"noise_smoothing": 0.5})
  assert np.abs(dancer.positions(z) - expected).max() <= 1e-4 * body_size(expected)
  assert not dancer.meta["decoding"]["ground"] and not dancer.meta["decoding"]["lock_feet"]
  assert np.abs(joints - expected).max() <= 1e-4 * body_size(expected)  # the graph's joints are the sample's


def test_a_gan_run_exports_its_generator_one_frame_a_call(tmp_path):
  """A tiny LSTM-GAN (bone directions, per-frame noise): 600 frames of two dancers from onnxruntime are `chorjax
  sample`'s, the noise vector read on each dancer's first frame and the frame noise every frame."""
  run_dir = trained(tmp_path / "gan", *GAN_NETWORKS, "gan.frame_noise=2")
  assert cli.main(["export", str(run_dir), "-o", str(tmp_path / "gan.onnx"), "--batch", "2"]) == 0
  run, dancer = load_run(run_dir), OnnxDancer(tmp_path / "gan.onnx")
  assert dancer.meta["family"] == "gan" and dancer.meta["normal_size"] == 8 + 2  # gan.latent_size + frame noise
  frames = 600
  gumbel, normal = sample_numbers(run, 7, frames, batch=2)
  weights = np.full((2, run.num_motions), 1.0 / run.num_motions, np.float32)  # a GAN reads no motion
  z, joints = dancer.dance(weights, gumbel, normal, joints=True)
  expected, _ = sample_dancers(run, frames, 2, 7)
  got = dancer.positions(z)
  assert got.shape == expected.shape and np.abs(got - expected).max() <= 1e-4 * body_size(expected)
  assert np.abs(joints - expected).max() <= 1e-4 * body_size(expected)  # bone directions, integrated in the graph


def exit_code(args) -> int:
  try:
    return cli.main(args)
  except SystemExit as e:  # argparse's refusals
    return int(e.code or 0)


def test_what_cannot_be_exported_is_refused_in_one_line_and_nothing_is_written(quickstart, tmp_path, capsys):
  out = ["-o", str(tmp_path / "d.onnx")]
  for flags, said in [
    ([*out, "--set", "sample.greedy=true"], "greedy"),
    (["-o", str(tmp_path / "d.glb")], "must end in .onnx"),
    ([*out, "--batch", "0"], "--batch"),
  ]:
    assert exit_code(["export", str(quickstart), *flags]) == 2
    err = capsys.readouterr().err
    assert said in err and "Traceback" not in err, err
  web = ["--web", str(tmp_path / "site")]
  for flags, said in [
    ([*web, *out], "no -o or --batch"),
    ([*web, "--ort-web", str(tmp_path)], "onnxruntime-web's files"),
    ([], "give -o DANCER.onnx or --web DIR"),
  ]:
    assert exit_code(["export", str(quickstart), *flags]) == 2
    err = capsys.readouterr().err
    assert said in err and "Traceback" not in err, err
  assert list(tmp_path.iterdir()) == []
  (tmp_path / "d.json").write_text("mine")  # a sidecar the user has is not replaced either
  assert cli.main(["export", str(quickstart), *out]) == 2
  assert "d.json: already exists" in capsys.readouterr().err and (tmp_path / "d.json").read_text() == "mine"
  assert not (tmp_path / "d.onnx").exists()
  (tmp_path / "d.json").unlink()
  (tmp_path / "d.json").mkdir()  # --force replaces files, not a folder (the dancer would lack its sidecar)
  assert cli.main(["export", str(quickstart), *out, "--force"]) == 2
  assert "is a folder" in capsys.readouterr().err and not (tmp_path / "d.onnx").exists()


def test_a_run_whose_meta_holds_no_number_is_not_exported_as_bare_nan(quickstart, tmp_path, capsys):
  """A run whose saved fps is NaN was exported with a bare ``NaN`` in its sidecar, which no JSON parser of a
  host reads; it is one line now, nothing written."""
  import shutil

  run = tmp_path / "run"
  shutil.copytree(quickstart, run)
  for path in run.glob("checkpoints/*/meta/metadata"):
    meta = json.loads(path.read_text())
    meta["fps"] = float("nan")  # the takes' frame rate (the config's data.fps is checked when read)
    path.write_text(json.dumps(meta))
  assert cli.main(["export", str(run), "-o", str(tmp_path / "d.onnx")]) == 2
  assert "NaN" in capsys.readouterr().err and not (tmp_path / "d.onnx").exists()


def khronos_validator(path: Path) -> dict:
  """The Khronos glTF validator's report of ``path``: ``{"errors", "warnings", "messages"}``."""
  import shutil
  import subprocess

  if shutil.which("node") is None or not (NODE_MODULES / "node_modules" / "gltf-validator").is_dir():
    pytest.fail(f"the Khronos glTF validator is missing: .ci/run installs it (npm install --prefix {NODE_MODULES} ...)")
  script = Path(__file__).with_name("validate_gltf.js")
  command = ["node", str(script), str(NODE_MODULES), str(path)]
  done = subprocess.run(command, capture_output=True, text=True, timeout=120)
  assert done.returncode == 0, done.stderr
  return json.loads(done.stdout)


def test_a_sample_written_as_gltf_is_valid_and_animates_the_joints_where_chorjax_put_them(quickstart, tmp_path):
  from chorjax.data.gltf import gltf_positions, read_glb_positions
  from chorjax.data.npz import read_npz

  draw = ["--frames", "90", "--num", "2", "--seed", "4"]
  assert cli.main(["sample", str(quickstart), "-o", str(tmp_path / "dance.glb"), *draw]) == 0
  assert cli.main(["sample", str(quickstart), "-o", str(tmp_path / "dance.npz"), *draw]) == 0
  dancers = read_npz(tmp_path / "dance.npz")
  for k, motion in enumerate(dancers):
    glb = tmp_path / f"dance_{k}.glb"
    report = khronos_validator(glb)
    assert report["errors"] == 0 and report["warnings"] == 0, report
    want, _ = gltf_positions(motion)
    got = read_glb_positions(glb)
    assert got.shape == want.shape == (90, motion.skeleton.num_joints, 3)
    assert np.abs(got - want).max() <= 1e-4 * body_size(want)


def test_a_take_in_millimetres_with_z_up_becomes_y_up_metres(tmp_path):
  """glTF is y-up in metres: a z-up take in millimetres is turned and scaled (and says so in its extras)."""
  import pygltflib

  from chorjax.api import Motion
  from chorjax.data.dataset import bundled_path
  from chorjax.data.gltf import read_glb_positions
  from chorjax.data.transforms import to_y_up

  take = Motion.of(read_csv(bundled_path("cmu94") / "94_05_skeleton_3d.csv"))
  y_up = np.asarray(to_y_up(take.positions[:60].astype(np.float64), take.up_axis))
  z_up = np.stack([y_up[..., 0], -y_up[..., 2], y_up[..., 1]], -1) * 1000.0  # y up -> z up, metres -> mm
  take.replace(positions=z_up, up_axis="z", units="mm").write(tmp_path / "take.glb")
  assert khronos_validator(tmp_path / "take.glb")["errors"] == 0
  np.testing.assert_allclose(read_glb_positions(tmp_path / "take.glb"), y_up, atol=1e-4 * body_size(y_up))
  extras = pygltflib.GLTF2().load_binary(str(tmp_path / "take.glb")).asset.extras
  assert extras["source_units"] == "mm" and extras["metres_per_unit"] == 0.001 and extras["fps"] == take.fps


def test_the_web_page_dances_offline_and_draws_what_onnxruntime_draws(quickstart, tmp_path):
  """`chorjax export --web`: served by a plain static server, with every other host unreachable, the page in
  headless Chromium dances for 10 s (the figure moves, no NaN, no console error), and its first 100 frames of
  seed 0 and their joints are onnxruntime-python's, drawn with the page's random numbers."""
  import functools
  import html
  import re
  import threading
  from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer

  from helpers import headless

  from chorjax.export.web import page_numbers

  ort_web = NODE_MODULES / "node_modules" / "onnxruntime-web" / "dist"
  if not ort_web.is_dir():
    pytest.fail(f"onnxruntime-web is missing: .ci/run installs it (npm install --prefix {NODE_MODULES} ...)")
  site = tmp_path / "site"
  assert cli.main(["export", str(quickstart), "--web", str(site), "--ort-web", str(ort_web)]) == 0
  assert sorted(p.name for p in site.iterdir()) == ["dancer.json", "dancer.onnx", "index.html", "ort"]
  assert "MIT License" in (site / "ort" / "LICENSE").read_text()
  # takes named as numbers ("10", "9", ... "1" for ids 0, 1, ...): JavaScript lists such keys in numeric order
  sidecar = json.loads((site / "dancer.json").read_text())
  count = len(sidecar["motions"])
  sidecar["motions"] = {str(count - i): i for i in range(count)}
  (site / "dancer.json").write_text(json.dumps(sidecar))

  quiet = type("Quiet", (SimpleHTTPRequestHandler,), {"log_message": lambda *a: None})
  server = ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(quiet, directory=str(site)))
  threading.Thread(target=server.serve_forever, daemon=True).start()
  try:
    url = f"http://127.0.0.1:{server.server_address[1]}/index.html#selftest"
    offline = "--host-resolver-rules=MAP * ~NOTFOUND , EXCLUDE 127.0.0.1"
    dom = headless(tmp_path / "profile", url, offline, "--virtual-time-budget=20000", "--dump-dom").stdout
  finally:
    server.shutdown()
  assert "<title>chorjax dancer: done</title>" in dom, dom[:2000]
  report = json.loads(html.unescape(re.search(r'<pre id="selftest">(.*?)</pre>', dom, re.S).group(1)))
  assert report["errors"] == [] and not report["nan"], report["errors"]
  assert report["seconds"] >= 10 and report["shown"] >= 250 and report["moved"] > 0
  assert report["menu"] == [f"{i}: {count - i}" for i in range(count)]  # motion i is the take of id i

  dancer = OnnxDancer(site / "dancer.onnx")
  gumbel, normal = page_numbers(0, 100, 1, dancer.meta["num_mixtures"], dancer.meta["normal_size"])
  weights = np.eye(len(dancer.meta["motions"]), dtype=np.float32)[:1]
  frames, joints = dancer.dance(weights, gumbel, normal, joints=True)
  np.testing.assert_allclose(np.asarray(report["frames"]), frames[0], atol=1e-4)
  y_up = joints[0] @ np.asarray(dancer.meta["skeleton"]["to_y_up"]).T  # the page draws y-up
  np.testing.assert_allclose(np.asarray(report["joints"]), y_up, atol=1e-4 * body_size(y_up))


def test_blenders_gltf_importer_puts_the_joints_where_chorjax_put_them(tmp_path):
  """Blender's own glTF importer (bpy, headless) reads a written take's nodes and animation: at every frame
  each joint is where chorjax's positions are (glTF's y-up turned into Blender's z-up)."""
  import subprocess

  from chorjax.api import Motion
  from chorjax.data.dataset import bundled_path
  from chorjax.data.gltf import gltf_positions

  if not BLENDER_PYTHON.exists():
    pytest.fail(f"Blender's Python is missing: .ci/run installs the bpy package into {BLENDER_PYTHON.parents[1]}")
  take = Motion.of(read_csv(bundled_path("cmu94") / "94_05_skeleton_3d.csv"))
  take = take.replace(positions=take.positions[:90])
  take.write(tmp_path / "take.glb")
  names = list(take.skeleton.joint_names)
  script = Path(__file__).with_name("blender_positions.py")
  args = [str(BLENDER_PYTHON), str(script), str(tmp_path / "take.glb"), str(int(take.fps)), "90", json.dumps(names)]
  done = subprocess.run(args, capture_output=True, text=True, timeout=300)
  assert done.returncode == 0, done.stderr[-2000:]
  (line,) = [line for line in done.stdout.splitlines() if line.startswith("POSITIONS")]
  z_up = np.asarray(json.loads(line.removeprefix("POSITIONS")))
  got = np.stack([z_up[..., 0], z_up[..., 2], -z_up[..., 1]], -1)  # Blender's (x, y, z) is glTF's (x, -z, y)
  want, _ = gltf_positions(take)
  assert got.shape == want.shape and np.abs(got - want).max() <= 1e-4 * body_size(want)


def test_a_run_moved_away_from_its_deleted_takes_samples_exports_and_goes_live(tmp_path):
  """Everything the quick start's draw needs from the training takes (ranges, steps, pace, floor and the scale
  ceiling of ``sample.scale_cap``) is saved with the run: a run folder moved elsewhere, its takes deleted,
  still samples, exports and streams; a scale quantile it never recorded names the missing takes in one line."""
  import shutil

  from chorjax.live.server import Stream

  takes = tmp_path / "takes"
  shutil.copytree(bundled_path("cmu94"), takes)
  sampling = [*QUICKSTART_SAMPLING, "sample.scale_cap=0.97", "model.mdn_basis=pca", "sample.ground=true"]
  run_dir = trained(tmp_path / "run", "train.num_steps=4", f"data.dataset={takes}", *sampling)
  moved = tmp_path / "elsewhere" / "run"
  moved.parent.mkdir()
  shutil.move(run_dir, moved)
  shutil.rmtree(takes)
  assert cli.main(["sample", str(moved), "-o", str(tmp_path / "s.csv"), "--frames", "30"]) == 0
  assert cli.main(["export", str(moved), "-o", str(tmp_path / "d.onnx")]) == 0
  run = load_run(moved)
  controls = run.sampling()
  assert controls.scale_cap and controls.pace and controls.clamp and controls.ground  # all of them in use
  stream = Stream(run.ranged(controls), controls, motion_weight_vector(run.num_motions), seed=0, chunk=5)
  assert np.isfinite(stream.next_chunk()).all()
  with pytest.raises(UserError, match="training data, which cannot be read"):
    run.ranged(controls.replace(scale_cap=0.5))


def test_the_web_export_says_it_needs_a_server_and_serves_itself(quickstart, tmp_path, capsys):
  """Opened from disk the page cannot fetch its dancer: ``--web DIR`` says so and how to serve it, and
  ``--web DIR --serve PORT`` serves it on 127.0.0.1 (index, dancer and sidecar) until interrupted."""
  import signal
  import subprocess
  import sys
  import urllib.request

  ort_web = NODE_MODULES / "node_modules" / "onnxruntime-web" / "dist"
  if not ort_web.is_dir():
    pytest.fail(f"onnxruntime-web is missing: .ci/run installs it (npm install --prefix {NODE_MODULES} ...)")
  assert cli.main(["export", str(quickstart), "--web", str(tmp_path / "a"), "--ort-web", str(ort_web)]) == 0
  said = capsys.readouterr().out
  assert "not from disk" in said and "--serve" in said and "http.server" in said
  assert cli.main(["export", str(quickstart), "-o", str(tmp_path / "d.onnx"), "--serve"]) == 2
  assert "--web" in capsys.readouterr().err
  site = tmp_path / "b"
  args = ["export", str(quickstart), "--web", str(site), "--ort-web", str(ort_web), "--serve", "0"]
  code = f"import sys; from chorjax import cli; sys.exit(cli.main({args!r}))"
  proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
  try:
    line = proc.stdout.readline()
    url = line.split("serving it at ")[1].split()[0]
    for name in ("index.html", "dancer.json", "dancer.onnx"):
      with urllib.request.urlopen(url + name, timeout=30) as r:
        assert r.read() == (site / name).read_bytes()
  finally:
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=30) == 0


def test_web_force_replaces_only_a_page_it_wrote(quickstart, tmp_path, capsys, monkeypatch):
  """``--web DIR --force`` replaces a page written before, and refuses (exit 2, nothing touched) a folder
  holding anything else: the run itself, the working directory, a folder above it, a user's files."""
  ort_web = NODE_MODULES / "node_modules" / "onnxruntime-web" / "dist"
  if not ort_web.is_dir():
    pytest.fail(f"onnxruntime-web is missing: .ci/run installs it (npm install --prefix {NODE_MODULES} ...)")
  web = lambda folder: ["export", str(quickstart), "--web", str(folder), "--ort-web", str(ort_web), "--force"]
  site = tmp_path / "site"
  assert cli.main(web(site)) == 0
  (site / "index.html").write_text("old")
  assert cli.main(web(site)) == 0 and (site / "index.html").read_text() != "old"
  capsys.readouterr()
  mine = tmp_path / "mine"
  (mine / "inner").mkdir(parents=True)
  (mine / "notes.txt").write_text("keep")
  monkeypatch.chdir(mine)
  before = sorted(p.name for p in quickstart.iterdir())
  for folder in (quickstart, ".", mine / "inner" / "..", "inner/..", mine.parent):
    assert cli.main(web(folder)) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "--force replaces only a page it wrote" in err, err
  (site / "ort" / "user.js").write_text("mine")
  assert cli.main(web(site)) == 2 and "ort/user.js" in capsys.readouterr().err
  assert (mine / "notes.txt").read_text() == "keep" and sorted(p.name for p in quickstart.iterdir()) == before
