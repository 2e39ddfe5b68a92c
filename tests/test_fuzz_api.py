"""Property-based tests of the Python API: whatever a caller passes to ``Run.sample``, ``load_run``,
``read_motion``, ``Motion.write``, ``Motion.show`` and ``score``, the answer is a result or one ``UserError``,
never another exception; and every format chorjax writes reads back as it was written.

Profiles as in tests/test_fuzz.py (``CHORJAX_FUZZ``): ``ci`` (default: a few examples per function, a fixed
seed) and ``long`` (10,000 per function, random seeds):

    CHORJAX_FUZZ=long pytest tests/test_fuzz_api.py -n0 -q
"""

import os

import numpy as np
import pytest
from helpers import QUICKSTART_SAMPLING, tiny_config
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import chorjax
from chorjax.data.dataset import bundled_path
from chorjax.sampling.controls import Controls
from chorjax.training.driver import train_and_evaluate

settings.register_profile(
  "api_ci", max_examples=15, derandomize=True, deadline=None, suppress_health_check=list(HealthCheck)
)
settings.register_profile("api_long", max_examples=10_000, deadline=None, suppress_health_check=list(HealthCheck))
PROFILE = "api_long" if os.environ.get("CHORJAX_FUZZ") == "long" else "api_ci"
TAKE = bundled_path("cmu94") / "94_07_skeleton_3d.csv"

# What a careless or hostile caller passes: wrong types, out-of-range and non-finite numbers, odd text.
HOSTILE = st.one_of(
  st.none(),
  st.booleans(),
  st.integers(-(2**70), -1),
  st.integers(2**32, 2**70),
  st.floats(allow_nan=True, allow_infinity=True),
  st.text(max_size=6),
  st.lists(st.integers(0, 3), max_size=2),
  st.sampled_from(["\udcff", "nan", "1e308", "-1", "0x10", "1_0", "\u0661"]),
)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
  workdir = tmp_path_factory.mktemp("api_run")
  train_and_evaluate(tiny_config("log.tensorboard=false", *QUICKSTART_SAMPLING), workdir)
  return chorjax.load_run(workdir)


def _result_or_refused(call):
  """``call()``'s result, or None where it raised a UserError; any other exception fails the test."""
  try:
    return call()
  except chorjax.UserError as e:
    assert "\n" not in str(e).strip(), str(e)
    return None


def _finite(result) -> None:
  for m in result if isinstance(result, list) else [result]:
    assert np.isfinite(np.asarray(m.positions)).all()


@given(
  frames=st.one_of(st.integers(2, 40), HOSTILE),
  num=st.one_of(st.integers(1, 2), HOSTILE),
  seed=st.one_of(st.integers(0, 2**32 - 1), HOSTILE),
  controls=st.dictionaries(st.sampled_from([*Controls.names(), "temprature", "noise"]), HOSTILE, max_size=2),
)
@settings(settings.get_profile(PROFILE))
def test_run_sample_returns_finite_dance_or_one_user_error(run, frames, num, seed, controls):
  result = _result_or_refused(lambda: run.sample(frames=frames, num=num, seed=seed, **controls))
  if result is not None:
    _finite(result)


@given(checkpoint=st.one_of(st.sampled_from(["kept", "best", "latest", "2", 2]), HOSTILE))
@settings(settings.get_profile(PROFILE))
def test_load_run_returns_a_run_or_one_user_error(run, checkpoint):
  _result_or_refused(lambda: chorjax.load_run(run.workdir, checkpoint=checkpoint))


@given(path=st.one_of(st.sampled_from([str(TAKE), str(TAKE.parent), "/dev/zero", "/proc", "a\x00b.csv"]), HOSTILE))
@settings(settings.get_profile(PROFILE))
def test_read_motion_returns_motion_or_one_user_error(path):
  result = _result_or_refused(lambda: chorjax.read_motion(path))
  if result is not None:
    _finite(result)


@given(
  name=st.one_of(st.text(max_size=8), st.sampled_from(["a\x00b", "\udcff", "", ".", "..", "/proc/x", "sub/x"])),
  suffix=st.sampled_from([".csv", ".npz", ".bvh", ".html", ".txt", ""]),
  force=st.booleans(),
)
@settings(settings.get_profile(PROFILE))
def test_motion_write_writes_or_says_why_not_in_one_line(tmp_path_factory, name, suffix, force):
  take = chorjax.read_motion(str(TAKE)).replace(positions=chorjax.read_motion(str(TAKE)).positions[:20])
  folder = tmp_path_factory.mktemp("write")
  target = name + suffix if name.startswith("/") else str(folder / (name + suffix))
  _result_or_refused(lambda: take.write(target, force=force))


@given(others=st.lists(HOSTILE, max_size=2), title=st.one_of(st.text(max_size=8), HOSTILE))
@settings(settings.get_profile(PROFILE))
def test_motion_show_plays_or_says_why_not_in_one_line(others, title):
  take = chorjax.read_motion(str(TAKE))
  player = _result_or_refused(lambda: take.show(*others, title=title))
  if player is not None:
    assert "<script" in player.html and "iframe" in player._repr_html_()


@given(options=st.dictionaries(st.sampled_from(["window", "splits", "seed", "segment", "windw"]), HOSTILE, max_size=2))
@settings(settings.get_profile(PROFILE))
def test_score_scores_or_says_why_not_in_one_line(options):
  take = chorjax.read_motion(str(TAKE))
  result = _result_or_refused(lambda: chorjax.score(take, "cmu94/94_01_skeleton_3d.csv", **options))
  if result is not None:
    assert np.isfinite(result["speed"] if not isinstance(result["speed"], dict) else result["speed"]["mean"])


@given(
  start=st.integers(0, 200),
  scale=st.floats(0.001, 1000),
  shift=st.tuples(*[st.floats(-1e4, 1e4)] * 3),
  suffix=st.sampled_from([".csv", ".npz", ".bvh"]),
)
@settings(settings.get_profile(PROFILE))
def test_every_writer_round_trips_a_take_moved_and_scaled(tmp_path_factory, start, scale, shift, suffix):
  """A stretch of a real take, scaled and moved anywhere, written in each format and read back: the same
  positions to 1e-3 of its height (BVH: by inverse then forward kinematics)."""
  take = chorjax.read_motion(str(TAKE))
  pos = take.positions[start : start + 30] * np.float32(scale) + np.asarray(shift, np.float32)
  moved = take.replace(positions=pos.astype(np.float32))
  path = moved.write(tmp_path_factory.mktemp("round") / f"t{suffix}")
  back = chorjax.read_motion(str(path))
  idx = [back.skeleton.joint_names.index(n) for n in moved.skeleton.joint_names]
  height = float(np.ptp(pos[..., 1]))
  assert np.abs(np.asarray(back.positions)[:, idx] - pos).max() < 1e-3 * height + 1e-4 * float(np.abs(shift).max())


SECTIONS = ["data", "model", "train", "sample", "gan", "patch", "modle"]
KEYS = ["seq_length", "hidden_size", "batch_size", "pace", "val_tail", "labels", "size", "family", "nope"]


@given(
  config=st.dictionaries(st.sampled_from(SECTIONS), st.one_of(st.dictionaries(st.sampled_from(KEYS), HOSTILE), HOSTILE))
)
@settings(settings.get_profile(PROFILE))
def test_a_config_given_as_a_dict_loads_or_is_refused_in_one_line(config):
  """``chorjax.train(dict)`` reads the dict as a file's tables: a Config, or one UserError naming the key."""
  from chorjax.config import load_config

  _result_or_refused(lambda: load_config(config))


CELLS = st.one_of(st.text(max_size=6), st.sampled_from(["take", "walk", "94_07_skeleton_3d", '"a,b"', "x=y", ""]))


@given(rows=st.lists(st.lists(CELLS, min_size=1, max_size=3), min_size=1, max_size=4))
@settings(settings.get_profile(PROFILE))
def test_a_labels_csv_reads_or_is_refused_in_one_line(tmp_path_factory, rows):
  """Whatever a labels CSV holds (``data.labels``): labels for the takes, or one UserError."""
  import csv

  from chorjax.data.labels import read_labels

  path = tmp_path_factory.mktemp("labels") / "labels.csv"
  with path.open("w", newline="", encoding="utf-8", errors="surrogateescape") as f:
    csv.writer(f).writerows(rows)
  _result_or_refused(lambda: read_labels(str(path), ["94_07_skeleton_3d", "94_08_skeleton_3d"]))


@given(
  values=st.lists(st.floats(allow_nan=True, allow_infinity=True, width=32), min_size=1, max_size=3),
  frames=st.integers(0, 3),
  suffix=st.sampled_from([".glb", ".bvh", ".csv", ".npz"]),
)
@settings(settings.get_profile(PROFILE))
def test_any_positions_write_or_are_refused_in_one_line(tmp_path_factory, values, frames, suffix):
  """A motion of 0-3 frames holding any float (NaN, inf, huge, tiny): written, or refused in one line."""
  take = chorjax.read_motion(str(TAKE))
  pos = np.resize(np.asarray(values, np.float32), (frames, take.skeleton.num_joints, 3))
  target = tmp_path_factory.mktemp("odd") / f"m{suffix}"
  _result_or_refused(lambda: take.replace(positions=pos).write(target))


@given(
  batch=st.one_of(st.integers(1, 2), HOSTILE),
  controls=st.dictionaries(st.sampled_from(["pace", "clamp"]), HOSTILE, max_size=1),
)
@settings(settings.get_profile(PROFILE), max_examples=4 if PROFILE == "api_ci" else 10_000)  # an export: seconds
def test_run_export_writes_or_is_refused_in_one_line(run, tmp_path_factory, batch, controls):
  path = tmp_path_factory.mktemp("export") / "dancer.onnx"
  _result_or_refused(lambda: run.export(path, batch=batch, **controls))


@given(
  content=st.one_of(
    st.binary(max_size=2000),
    st.sampled_from([b"", b"PK\x03\x04", b"\x93NUMPY", b"PK\x05\x06" + bytes(18)]),
  ),
  cut=st.integers(0, 4000),
)
@settings(settings.get_profile(PROFILE))
def test_a_cache_entry_of_any_bytes_gives_back_the_take_read_anew(tmp_path_factory, content, cut):
  """The read cache (``data.cache``): an entry replaced by any bytes, or a real entry cut short, is made again
  from the take, never trusted: the take read through it is the take."""
  import contextlib
  import io

  from chorjax.data.cache import Cache
  from chorjax.data.dataset import read_motions

  root = tmp_path_factory.mktemp("cache")
  fresh = read_motions(TAKE)[0]
  with contextlib.redirect_stderr(io.StringIO()):
    Cache(root).motions(TAKE, {}, lambda: read_motions(TAKE))
    (entry,) = root.rglob("*.npz")
    entry.write_bytes(content if cut % 2 else entry.read_bytes()[:cut])
    again = Cache(root).motions(TAKE, {}, lambda: read_motions(TAKE))[0]
  np.testing.assert_array_equal(again.positions, fresh.positions)
  assert again.skeleton == fresh.skeleton and again.fps == fresh.fps
