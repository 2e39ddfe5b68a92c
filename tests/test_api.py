"""chorjax as a Python library: the API drives what the command line does, with the same results."""

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import SHARED
from helpers import TINY

import chorjax
from chorjax import cli
from chorjax.data.bvh import read_bvh
from chorjax.data.dataset import bundled_path
from chorjax.data.npz import read_npz


def test_train_sample_score_and_write_through_the_api_equal_the_command_line(tmp_path, capsys):
  run = chorjax.train(None, tmp_path / "run", [*TINY, "train.num_steps=3", "log.tensorboard=false"])
  assert isinstance(run, chorjax.Run) and run.step == 3
  again = chorjax.load_run(tmp_path / "run")
  dance = again.sample(frames=90, seed=3, pi_temperature=0.8)
  assert isinstance(dance, chorjax.Motion) and dance.positions.shape == (90, 16, 3)
  # what a notebook shows of them: one short line each, not every weight or every frame
  for obj, says in ((again, "step 3"), (dance, "90 frames"), (dance.show(), "KiB page"), (again.sampling(), "pace=")):
    text = repr(obj)
    assert says in text and len(text) < 300 and "\n" not in text, text
  assert (
    cli.main(
      [
        "sample",
        str(tmp_path / "run"),
        "-o",
        str(tmp_path / "cli.npz"),
        "--frames",
        "90",
        "--seed",
        "3",
        "--set",
        "sample.pi_temperature=0.8",
      ]
    )
    == 0
  )
  np.testing.assert_array_equal(read_npz(tmp_path / "cli.npz")[0].positions, dance.positions)  # the same draw
  several = again.sample(frames=30, num=2, seed=1, mix="0:1,1:1")
  assert len(several) == 2 and all(m.num_frames == 30 for m in several)
  scores = chorjax.score(dance, "cmu94/94_10_skeleton_3d.csv", splits=2, window=30)
  assert set(chorjax.api.metric_keys()) <= set(scores) and np.isfinite(scores["jitter"])
  out = dance.write(tmp_path / "dance.bvh")
  back = chorjax.read_motion(out)
  assert isinstance(back, chorjax.Motion) and back.num_frames == 90
  np.testing.assert_allclose(read_bvh(out).positions, chorjax.read_motion(out).positions)
  assert dance.write(tmp_path / "dance.csv").exists() and dance.write(tmp_path / "d.npz").exists()
  character = SHARED / "bvh" / "bandai" / "dataset-1_dance-short_normal_001.bvh"  # onto a character's rig
  on_rig = read_bvh(dance.write(tmp_path / "rig.bvh", skeleton=character))
  assert on_rig.skeleton.joint_names == read_bvh(character).skeleton.joint_names and on_rig.num_frames == 90
  with pytest.raises(chorjax.UserError, match="already exists"):
    dance.write(tmp_path / "dance.csv")  # nothing of the user's is replaced without force
  with pytest.raises(chorjax.UserError, match="no such run directory"):
    chorjax.load_run(tmp_path / "nope")
  with pytest.raises(chorjax.UserError, match="motion id 99 out of range"):
    again.sample(frames=10, mix="99:1")
  with pytest.raises(chorjax.UserError, match="unknown"):
    chorjax.train(None, tmp_path / "bad", ["model.hiden_size=3"])
  assert not (tmp_path / "bad").exists()


def test_motions_show_as_a_player_and_draw_as_a_strip(tmp_path):
  takes = chorjax.load_dataset("cmu94")
  assert len(takes) == 10 and all(isinstance(t, chorjax.Motion) for t in takes)
  player = takes[0].show(takes[1])
  page = player._repr_html_()
  assert page.startswith("<iframe srcdoc=") and "&lt;script&gt;" in page and "<script>" not in page
  assert "var MOTIONS" in player.html and player.save(tmp_path / "p.html").read_text() == player.html
  fig = takes[0].strip(every=10, poses=6)
  assert len(fig.axes) == 3  # start, middle, end


def test_import_chorjax_is_light_and_help_lists_the_api():
  code = "import sys, chorjax; print('jax' in sys.modules); help(chorjax)"
  out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
  assert out.startswith("False")  # the command line starts without jax; the API loads it on first use
  for name in ("train", "load_run", "read_motion", "load_dataset", "score", "class Motion", "class Run"):
    assert name in out, name


def test_motion_write_refuses_to_replace_a_sidecar_unless_forced(tmp_path):
  """A take of its own skeleton writes x.csv and x.skeleton.json: an existing sidecar is the user's file too."""
  import dataclasses

  from chorjax.data.csv import sidecar_path

  take = chorjax.load_dataset("cmu94")[0]
  names = tuple(f"j{k}" for k in range(take.skeleton.num_joints))
  own = chorjax.Motion.of(take.replace(skeleton=dataclasses.replace(take.skeleton, name="own", joint_names=names)))
  out = tmp_path / "x.csv"
  sidecar_path(out).write_text("mine")
  with pytest.raises(chorjax.UserError, match=r"x\.skeleton\.json: already exists \(use force=True"):
    own.write(out)
  assert sidecar_path(out).read_text() == "mine" and not out.exists()
  own.write(out, force=True)
  assert chorjax.read_motion(out).skeleton.joint_names == names


def test_motion_write_and_show_refuse_what_makes_no_sense_in_one_line(tmp_path):
  take = chorjax.load_dataset("cmu94")[0]
  (tmp_path / "taken.csv").mkdir()  # a folder where the file would go
  for path in (tmp_path / "a\x00b.csv", Path("/proc/x.csv"), tmp_path / "taken.csv"):
    with pytest.raises(chorjax.UserError):
      take.write(path, force=True)
  with pytest.raises(chorjax.UserError, match="title must be text"):
    take.show(title=5)
  with pytest.raises(chorjax.UserError, match="expected motions"):
    take.show("not a motion")


@pytest.mark.parametrize(
  "options, said",
  [
    ({"splits": 10**6}, "splits 1000000: must be a whole number from 1 to 1,000"),
    ({"splits": 2.5}, "splits 2.5"),
    ({"splits": True}, "splits True"),
    ({"window": 10**9}, "window 1000000000"),
    ({"seed": -1}, "seed -1"),
    ({"segment": 0}, "segment 0"),
    ({"windw": 30}, "'windw' is not a scoring option; did you mean 'window'?"),
  ],
)
def test_score_refuses_the_options_the_command_line_refuses(options, said):
  """One check serves `chorjax metrics` and chorjax.score: a million splits ran for minutes, a float seed was a
  raw TypeError, a misspelt option a raw TypeError."""
  take = chorjax.read_motion(str(bundled_path("cmu94") / "94_01_skeleton_3d.csv"))
  with pytest.raises(chorjax.UserError, match=re.escape(said)):
    chorjax.score(take, "cmu94", **options)


def test_a_name_with_a_lone_surrogate_writes_and_shows_as_a_replacement_character(tmp_path):
  """A file name's invalid byte decodes to a lone surrogate (os.fsdecode); the player page is UTF-8, so it was a
  UnicodeEncodeError. It is shown as U+FFFD."""
  take = chorjax.read_motion(str(bundled_path("cmu94") / "94_01_skeleton_3d.csv")).replace(name="take\udcff")
  page = take.write(tmp_path / "take.html").read_text(encoding="utf-8")
  assert "take\\udcff" in page  # the name, escaped inside the JSON the page reads
  shown = take.show(title="dance \udcff\ud800")._repr_html_()
  assert "dance \ufffd\ufffd" in shown
