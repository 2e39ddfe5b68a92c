"""Hostile input (issue 40): values that parse but make no sense, damaged runs and reports, files of the
user's that must not be overwritten, names that would escape the runs folder, and a last-resort line for
anything unforeseen. Each case: one line, exit 2 (or accepted where the input is valid), nothing written."""

import contextlib
import json
import os
import re
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import TINY, tiny_config

from chorjax import cli
from chorjax.data.bvh import read_bvh
from chorjax.errors import UserError
from chorjax.training.driver import train_and_evaluate

BVH = "bvh/cmu131/131_01.bvh"
QUICKSTART = str(Path(__file__).resolve().parents[1] / "configs" / "quickstart.toml")


def _one_line(capsys, *parts) -> str:
  err = capsys.readouterr().err.strip().splitlines()
  assert len(err) == 1 and "Traceback" not in err[0], err
  for p in parts:
    assert p in err[0], (p, err[0])
  return err[0]


def test_an_unforeseen_exception_is_one_line_that_says_it_is_a_bug(monkeypatch, capsys):
  monkeypatch.delenv("CHORJAX_DEBUG", raising=False)
  monkeypatch.setitem(cli.HANDLERS, "data_info", lambda args: [][1])
  assert cli.main(["data", "info", "cmu94"]) == 1
  _one_line(capsys, "internal error (IndexError: list index out of range)", "bug", "CHORJAX_DEBUG=1")
  monkeypatch.setenv("CHORJAX_DEBUG", "1")
  with pytest.raises(IndexError):
    cli.main(["data", "info", "cmu94"])


def test_readers_accept_a_byte_order_mark_and_a_joint_named_like_a_section(shared_data, tmp_path, capsys):
  text = (shared_data / BVH).read_text()
  first = read_bvh(shared_data / BVH)
  (tmp_path / "bom.bvh").write_bytes(b"\xef\xbb\xbf" + text.encode())
  np.testing.assert_array_equal(read_bvh(tmp_path / "bom.bvh").positions, first.positions)
  (tmp_path / "motion.bvh").write_text(
    text.replace("JOINT Chest2", "JOINT MOTIONSpine").replace("JOINT Chest\n", "JOINT Chest\n")
  )
  renamed = read_bvh(tmp_path / "motion.bvh")
  assert "MOTIONSpine" in renamed.skeleton.joint_names
  np.testing.assert_array_equal(renamed.positions, first.positions)
  (tmp_path / "c.toml").write_bytes(b"\xef\xbb\xbf" + b'name = "bom"\n[model]\nhidden_size = 16\n')
  assert cli.main(["config", "show", str(tmp_path / "c.toml")]) == 0
  assert "hidden_size = 16" in capsys.readouterr().out


def test_rates_and_axes_that_make_no_sense_are_refused_where_they_are_read(shared_data, tmp_path, capsys):
  text = (shared_data / BVH).read_text()
  (tmp_path / "slow.bvh").write_text(re.sub(r"Frame Time:\s*\S+", "Frame Time: 999", text))
  assert cli.main(["data", "info", str(tmp_path / "slow.bvh")]) == 2
  _one_line(capsys, "slow.bvh: Frame Time 999", "outside 1-1000 fps")
  from chorjax.data.npz import write_npz
  from chorjax.data.skeletons import MPII16

  path = write_npz(
    tmp_path / "s.npz", np.zeros((1, 5, 16, 3)), fps=30.0, skeleton=MPII16, up_axis="y", units="x", settings={}
  )
  with np.load(path) as z:
    meta = json.loads(str(z["meta"]))
  for key, value, said in (
    ("fps", 0.0, "frame rate 0 fps"),
    ("fps", 1e300, "outside"),
    ("up_axis", "w", "up axis 'w'"),
  ):
    bad = tmp_path / f"bad_{key}.npz"
    np.savez(bad, positions=np.zeros((1, 5, 16, 3), np.float32), meta=np.array(json.dumps({**meta, key: value})))
    assert cli.main(["data", "info", str(bad)]) == 2
    _one_line(capsys, str(bad), said)


@pytest.mark.parametrize(
  "override, said",
  [
    ("train.seed=99999999999999999999", "train.seed"),
    ("model.dropout=1.5", "model.dropout"),
    ("optim.b2=2", "optim.b2"),
    ("data.fps=0.001", "data.fps"),
    ("name=../../x", "plain file name"),
  ],
)
def test_config_values_out_of_range_and_names_that_escape_are_one_line(tmp_path, capsys, override, said):
  assert cli.main(["train", QUICKSTART, "--workdir", str(tmp_path / "w"), *TINY, override]) == 2
  _one_line(capsys, said)
  assert not (tmp_path / "w").exists()


def test_flags_out_of_range_are_one_line(capsys):
  assert cli.main(["live", "runs/x", "--port", "70000"]) == 2
  _one_line(capsys, "--port 70000: must be at most 65535")
  with pytest.raises(SystemExit) as e:  # argparse's own line
    cli.main(["data", "plot", "cmu94", "-o", "p.png", "--split", "-5"])
  assert e.value.code == 2 and "--split" in capsys.readouterr().err


def test_a_named_pipe_among_the_takes_is_refused_without_blocking(tmp_path, capsys):
  os.mkfifo(tmp_path / "pipe.csv")
  assert cli.main(["data", "info", str(tmp_path / "pipe.csv")]) == 2
  _one_line(capsys, "pipe.csv: not a regular file")


def test_a_sweep_value_that_would_name_a_folder_outside_the_runs_is_refused(tmp_path, capsys):
  sweep = tmp_path / "s.toml"
  sweep.write_text('name = "s"\n[grid]\n"data.dataset" = ["../elsewhere"]\n')
  assert cli.main(["sweep", str(sweep)]) == 2
  _one_line(capsys, "sweep point", "plain file name")


def test_training_into_a_folder_of_the_users_is_refused_unless_forced(tmp_path, capsys):
  mine = tmp_path / "mine"
  mine.mkdir()
  (mine / "samples").mkdir()
  (mine / "samples" / "notes.txt").write_text("mine")
  assert cli.main(["train", QUICKSTART, "--workdir", str(mine), *TINY]) == 2
  _one_line(capsys, "is not a chorjax run")
  assert sorted(p.name for p in mine.rglob("*")) == ["notes.txt", "samples"]  # nothing written


def test_a_run_resumes_past_a_torn_metrics_line_and_compare_names_a_damaged_evaluation(tmp_path, capsys):
  w = tmp_path / "run"
  train_and_evaluate(tiny_config("train.num_steps=2", "log.tensorboard=false"), w)
  with open(w / "metrics.jsonl", "a") as f:
    f.write('{"step": 3, "train_lo')  # what a kill mid-write leaves
  train_and_evaluate(tiny_config("train.num_steps=4", "log.tensorboard=false"), w)  # resumes at step 2
  assert "dropped 1 unreadable line(s)" in capsys.readouterr().out
  rows = [json.loads(line) for line in (w / "metrics.jsonl").read_text().splitlines()]
  assert [r["step"] for r in rows] == [1, 2, 3, 4]
  (w / "eval").mkdir()
  (w / "eval" / "metrics.json").write_text('{"frames": 10, "nu')
  assert cli.main(["compare", str(w), "-o", str(tmp_path / "r.md")]) == 2
  _one_line(capsys, "metrics.json: damaged evaluation (not JSON")
  (w / "eval" / "metrics.json").write_text('{"frames": 10}')
  assert cli.main(["compare", str(w), "-o", str(tmp_path / "r.md")]) == 2
  _one_line(capsys, "not a whole evaluation")
  (tmp_path / "r_loss.png").write_bytes(b"my picture")
  assert cli.main(["compare", str(w), "-o", str(tmp_path / "r.md")]) == 2
  _one_line(capsys, "r_loss.png: already exists")
  assert (tmp_path / "r_loss.png").read_bytes() == b"my picture"


def _bvh_mutations(text: str) -> dict:
  """Damaged copies of a real BVH, each of which used to be read silently as some other skeleton."""
  head, motion = text.split("MOTION", 1)
  close = head.rstrip().rfind("}")
  return {
    "extra_brace": (head.rstrip() + "\n}\n" + "MOTION" + motion, "unexpected '}' after the ROOT"),
    "second_root": (head.rstrip() + "\nROOT Other\n{\n OFFSET 0 0 0\n}\nMOTION" + motion, "'ROOT' after the ROOT"),
    "junk_after_root": (head[: close + 1] + "\nOOPS\n" + head[close + 1 :] + "MOTION" + motion, "'OOPS' after"),
    "three_x": (
      text.replace("CHANNELS 3 Zrotation Yrotation Xrotation", "CHANNELS 3 Xrotation Xrotation Xrotation", 1),
      "repeated channel",
    ),
    "duplicate_name": (text.replace("JOINT LeftKnee", "JOINT LeftHip", 1), "joint name 'LeftHip' is used twice"),
    "nested_root": (text.replace("JOINT LHipJoint", "ROOT LHipJoint", 1), "inside another joint"),
    "offset_first": (text.replace("HIERARCHY", "HIERARCHY\nOFFSET 0 0 0", 1), "OFFSET outside a joint"),
    # numbers as no mocap tool writes them, though Python's int() and float() read them
    "other_digits": (re.sub(r"CHANNELS 3", "CHANNELS \u0663", text, count=1), "CHANNELS needs a count"),
    "underscore_frames": (re.sub(r"Frames:\s*(\d)", r"Frames: 1_\1", text, count=1), "expected 'Frames: N'"),
    "underscore_value": (
      re.sub(r"(Frame Time:[^\n]*\n\s*)(\S+)", r"\g<1>1_0", text, count=1),
      "not a plain decimal number: '1_0'",
    ),
  }


@pytest.mark.parametrize(
  "case",
  [
    "extra_brace",
    "second_root",
    "junk_after_root",
    "three_x",
    "duplicate_name",
    "nested_root",
    "offset_first",
    "other_digits",
    "underscore_frames",
    "underscore_value",
  ],
)
def test_bvh_structure_is_strict(shared_data, tmp_path, capsys, case):
  text, said = _bvh_mutations((shared_data / BVH).read_text())[case]
  path = tmp_path / f"{case}.bvh"
  path.write_text(text)
  assert cli.main(["data", "info", str(path)]) == 2
  _one_line(capsys, f"{case}.bvh:", said)


def _asf_amc_mutations(asf: str, amc: str) -> dict:
  assert re.search(r"^2$", amc, flags=re.M)
  return {
    "gradians": (asf.replace("angle deg", "angle gradians"), amc, "angle unit 'gradians'"),
    "zero_length_unit": (asf.replace("length 0.45", "length 0"), amc, "length unit 0"),
    "axis_order": (asf.replace("axis 0 0 20  XYZ", "axis 0 0 20  XYY", 1), amc, "axis order 'XYY'"),
    "dof": (asf.replace("dof rx ry rz", "dof rx rq rz", 1), amc, "unknown or repeated channel"),
    "bone_twice": (asf.replace("name lfemur", "name lhipjoint", 1), amc, "bone name 'lhipjoint' is used twice"),
    "frames_out_of_order": (asf, amc.replace("\n2\n", "\n3\n", 1), "frame 3 follows frame 1"),
    "bone_twice_in_frame": (
      asf,
      re.sub(r"^(lowerback .*)$", r"\1\n\1", amc, count=1, flags=re.M),
      "twice in one frame",
    ),
    "superscript_frame": (asf, amc.replace("\n2\n", "\n\u00b2\n", 1), "bone '\u00b2' is not in the skeleton"),
    "underscore_value": (asf, re.sub(r"^(root) (\S+)", r"\1 4_2", amc, count=1, flags=re.M), "'4_2'"),
    "zero_direction": (
      asf.replace("direction 0.653368 -0.678499 0.335782", "direction 0 0 0", 1),
      amc,
      "zero direction",
    ),
    "undefined_bone": (asf.replace("lhipjoint lfemur", "lhipjoint lfemur ghost", 1), amc, "bone 'ghost'"),
  }


@pytest.mark.parametrize(
  "case",
  [
    "gradians",
    "zero_length_unit",
    "axis_order",
    "dof",
    "bone_twice",
    "frames_out_of_order",
    "bone_twice_in_frame",
    "superscript_frame",
    "underscore_value",
    "zero_direction",
    "undefined_bone",
  ],
)
def test_asf_and_amc_structure_is_strict(shared_data, tmp_path, capsys, case):
  folder = shared_data / "asfamc" / "cmu05"
  asf, amc, said = _asf_amc_mutations((folder / "moderndance.asf").read_text(), (folder / "md_02.amc").read_text())[
    case
  ]
  (tmp_path / "moderndance.asf").write_text(asf)
  (tmp_path / "md_02.amc").write_text(amc)
  assert cli.main(["data", "info", str(tmp_path / "md_02.amc")]) == 2
  _one_line(capsys, "moderndance.asf:" if amc == (folder / "md_02.amc").read_text() else "md_02.amc:", said)


def test_an_npz_header_is_never_trusted_for_an_allocation(tmp_path, capsys):
  import io
  import zipfile

  buf = io.BytesIO()  # a header claiming 17.5 TiB over 64 bytes of data: numpy would allocate it first
  np.lib.format.write_array_header_1_0(
    buf, {"descr": "<f4", "fortran_order": False, "shape": (1, 100_000_000_000, 16, 3)}
  )
  with zipfile.ZipFile(tmp_path / "huge.npz", "w") as z:
    z.writestr("positions.npy", buf.getvalue() + b"\0" * 64)
    z.writestr("meta.npy", b"")
  assert cli.main(["data", "info", str(tmp_path / "huge.npz")]) == 2
  _one_line(capsys, "huge.npz: positions.npy claims 19,200,000,000,000 bytes")


def test_a_refused_start_leaves_no_files_behind(tmp_path, capsys):
  new, empty = tmp_path / "new", tmp_path / "empty"
  empty.mkdir()
  for workdir in (new, empty):
    for bad in ("data.dataset=nowhere", 'data.val_takes=["nope"]'):
      assert cli.main(["train", QUICKSTART, "--workdir", str(workdir), *TINY, bad]) == 2
      _one_line(capsys, "error:")
  assert not new.exists() and list(empty.iterdir()) == []  # was: .lock (and config.json, checkpoints/)


def _frozen_takes(folder: Path) -> dict:
  from chorjax.data.dataset import bundled_path

  rows = (bundled_path("cmu94") / "94_01_skeleton_3d.csv").read_text().splitlines()
  folder.mkdir(exist_ok=True)
  made = {"frozen": [rows[0]] * 300, "two": rows[:2], "zeros": [",".join(["0"] * 48)] * 300}
  for name, lines in made.items():
    (folder / f"{name}.csv").write_text("\n".join(lines) + "\n")
  return {name: folder / f"{name}.csv" for name in made}


def test_degenerate_references_and_takes_are_named_not_divided_by(tmp_path, capsys):
  from chorjax.data.dataset import bundled_path, dataset_notes, load_dataset

  takes = _frozen_takes(tmp_path / "odd")
  real = str(bundled_path("cmu94") / "94_01_skeleton_3d.csv")
  for name, said in (("frozen", "do not move (frozen)"), ("two", "shorter than half a second"), ("zeros", "no body")):
    assert cli.main(["metrics", real, "--data", str(takes[name])]) == 2  # were ZeroDivisionError / ValueError
    _one_line(capsys, "--data: the reference takes", said)
  assert cli.main(["data", "check", str(takes["zeros"])]) == 2
  _one_line(capsys, "zeros.csv: every joint of every frame at one point")
  dance = tmp_path / "dance"
  dance.mkdir()
  (dance / "94_01.csv").write_text(Path(real).read_text())
  (dance / "frozen.csv").write_text(takes["frozen"].read_text())
  cfg = tiny_config(f"data.dataset={dance}", 'data.val_takes=["94_01"]')
  assert "warning: take frozen does not move" in "\n".join(dataset_notes(load_dataset(cfg.data)))
  (dance / "94_01.csv").unlink()
  with pytest.raises(UserError, match="no take moves"):
    load_dataset(tiny_config(f"data.dataset={dance}", "data.val_takes=[]").data)


def test_a_deep_hierarchy_a_character_with_twin_names_and_one_name_in_two_formats(shared_data, tmp_path, capsys):
  from chorjax.data.retarget import Character

  lines = [
    "HIERARCHY",
    "ROOT r",
    "{",
    "OFFSET 0 0 0",
    "CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation",
  ]
  for i in range(3000):  # was a RecursionError
    lines += [f"JOINT j{i}", "{", "OFFSET 0 1 0", "CHANNELS 3 Zrotation Yrotation Xrotation"]
  lines += ["End Site", "{", "OFFSET 0 1 0", "}", *["}"] * 3001, "MOTION", "Frames: 2", "Frame Time: 0.033333"]
  lines += [" ".join(["0"] * (6 + 3 * 3000))] * 2
  (tmp_path / "deep.bvh").write_text("\n".join(lines) + "\n")
  assert read_bvh(tmp_path / "deep.bvh").positions.shape == (2, 3002, 3)
  text = (shared_data / BVH).read_text()  # a character with two joints of one name looped forever in retargeting
  (tmp_path / "twins.bvh").write_text(text.replace("JOINT LeftKnee", "JOINT LeftHip", 1))
  with pytest.raises(UserError, match="joint name 'LeftHip' is used twice"):
    Character(tmp_path / "twins.bvh")
  both = tmp_path / "both"  # one take's name in two formats: two takes, both read
  both.mkdir()
  (both / "t.bvh").write_text(text)
  from chorjax.data.csv import write_csv

  write_csv(read_bvh(shared_data / BVH), both / "t.csv")
  assert cli.main(["data", "check", str(both)]) == 0  # was a KeyError: takes were keyed by name
  out = capsys.readouterr().out
  assert "t.bvh" in out and "t.csv" in out


def test_a_c3d_point_rate_of_zero_is_named(shared_data, tmp_path, capsys):
  raw = bytearray((shared_data / "c3d" / "ezc3d" / "Qualisys.c3d").read_bytes())
  at = raw.index(b"\x04\x01RATE", (raw[0] - 1) * 512) + 2 + 4 + 4  # group 1 (POINT): name, next-offset, type, dims
  assert struct.unpack("<f", raw[at : at + 4]) == (200.0,)
  raw[at : at + 4] = struct.pack("<f", 0.0)
  raw[20:24] = struct.pack("<f", 0.0)  # and the header's rate (ezc3d prefers it)
  (tmp_path / "rate0.c3d").write_bytes(bytes(raw))
  assert cli.main(["data", "info", str(tmp_path / "rate0.c3d")]) == 2  # was a ZeroDivisionError downstream
  _one_line(capsys, "rate0.c3d: POINT:RATE", "outside 1-1000 fps")


def test_two_takes_of_one_name_are_refused_before_either_is_written(tmp_path, capsys):
  """`data convert a/t.bvh b/t.bvh -o OUT` would write OUT/t.csv twice: one take lost without a word."""
  take = Path(__file__).resolve().parents[1] / "chorjax" / "data" / "bundled" / "cmu94" / "94_01_skeleton_3d.csv"
  for d in ("a", "b"):
    (tmp_path / d).mkdir()
    assert cli.main(["data", "convert", str(take), "-o", str(tmp_path / d / "t.bvh")]) == 0
  capsys.readouterr()
  out = tmp_path / "out"
  assert (
    cli.main(["data", "convert", str(tmp_path / "a" / "t.bvh"), str(tmp_path / "b" / "t.bvh"), "-o", str(out)]) == 2
  )
  _one_line(capsys, "a/t.bvh and", "b/t.bvh would both be written to", "t.csv")
  assert not out.exists()


@pytest.mark.parametrize(
  ("argv", "said"),
  [
    (["data", "check", "cmu94", "--fps", "1e300"], "1e300: must be a number from 1 to 1000"),
    (["data", "check", "cmu94", "--fps", "0"], "0: must be a number from 1 to 1000"),
    (["data", "convert", "cmu94", "-o", "{tmp}/o", "--scale", "1e38"], "1e38: must be a number from 1e-06 to 1e+06"),
    (["render", "cmu94", "-o", "{tmp}/r.html", "--columns", "-3"], "--columns -3: must be at least 1"),
    (["metrics", "cmu94", "--data", "cmu94", "-o", "{tmp}/m.csv"], "m.csv: output must end in .json"),
  ],
)
def test_flags_that_make_no_sense_are_one_line_and_write_nothing(tmp_path, capsys, argv, said):
  try:
    code = cli.main([a.replace("{tmp}", str(tmp_path)) for a in argv])
  except SystemExit as e:  # argparse's own refusal of a flag's value
    code = e.code
  assert code == 2
  assert said in capsys.readouterr().err
  assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("number", ["1_0", "\u0661\u0662", "\uff11\uff12", "4_2.5e1_0"])
def test_a_csv_number_no_mocap_tool_writes_is_named(tmp_path, capsys, number):
  """Python's float() reads underscores and other scripts' digits; a take's file holds ASCII decimals only."""
  from chorjax.data.dataset import bundled_path

  lines = (bundled_path("cmu94") / "94_01_skeleton_3d.csv").read_text().splitlines()[:30]
  cells = lines[6].split(",")
  cells[2] = number
  lines[6] = ",".join(cells)
  (tmp_path / "odd.csv").write_text("\n".join(lines) + "\n")
  assert cli.main(["data", "info", str(tmp_path / "odd.csv")]) == 2
  _one_line(capsys, "odd.csv:7: column 3", "not a plain decimal number")


def test_an_npz_of_no_dancers_complex_values_or_a_zip_bomb_is_named(tmp_path, capsys):
  import zipfile

  import chorjax

  chorjax.read_motion(str(Path(__file__).parents[1] / "chorjax/data/bundled/cmu94/94_01_skeleton_3d.csv")).write(
    tmp_path / "ok.npz"
  )
  good = dict(np.load(tmp_path / "ok.npz"))
  np.savez(tmp_path / "none.npz", positions=good["positions"][:0], meta=good["meta"])
  np.savez(tmp_path / "complex.npz", positions=good["positions"] + 1j, meta=good["meta"])
  frames = 300 << 20 >> 8  # 300 MiB of zeros in rows of 16 x 3 float32 + padding: deflates about 1000x
  with zipfile.ZipFile(tmp_path / "bomb.npz", "w", zipfile.ZIP_DEFLATED) as z:
    with z.open("positions.npy", "w", force_zip64=True) as f:
      np.lib.format.write_array_header_1_0(f, {"descr": "<f4", "fortran_order": False, "shape": (1, frames, 16, 4)})
      zeros = bytes(1 << 20)
      for _ in range(300):
        f.write(zeros)
    z.writestr("meta.npy", b"")
  for name, said in (
    ("none", "expected [K >= 1"),
    ("complex", "positions are complex64 values, not real numbers"),
    ("bomb", "positions.npy inflates from"),
  ):
    assert cli.main(["data", "info", str(tmp_path / f"{name}.npz")]) == 2, name
    _one_line(capsys, f"{name}.npz:", said)


def test_nesting_too_deep_for_a_parser_and_a_device_as_a_file_are_one_line(shared_data, tmp_path, capsys):
  """Python's TOML and JSON parsers recurse: a file nested thousands deep must be one line, not a
  RecursionError; a device (/dev/zero) given as a config or sweep file must be refused, not read forever."""
  deep = "[" * 5000 + "]" * 5000
  (tmp_path / "deep.toml").write_text(f"a = {deep}\n")
  (tmp_path / "sweep.toml").write_text(f'name = "s"\nbase = "{QUICKSTART}"\n[grid]\n"train.seed" = {deep}\n')
  (tmp_path / "map.toml").write_text(f"pelvis = {deep}\n")
  (tmp_path / "t.skeleton.json").write_text(deep)
  (tmp_path / "t.csv").write_text("0," * 47 + "0\n")
  cases = [
    (["config", "show", str(tmp_path / "deep.toml")], "deep.toml: invalid TOML: nested too deeply"),
    (["config", "show", QUICKSTART, f"model.hidden_size={deep}"], "model.hidden_size=[[["),
    (["sweep", str(tmp_path / "sweep.toml")], "sweep.toml: invalid TOML: nested too deeply"),
    (
      [
        "data",
        "convert",
        str(shared_data / BVH),
        "-o",
        str(tmp_path / "o"),
        "--joint-map",
        str(tmp_path / "map.toml"),
        "--joints",
        "mpii16",
      ],
      "map.toml",
    ),
    (["data", "info", str(tmp_path / "t.csv")], "t.skeleton.json"),
    (["config", "show", "/dev/zero"], "/dev/zero: not a regular file"),
    (["sweep", "/dev/zero"], "/dev/zero: not a regular file"),
  ]
  for argv, said in cases:
    assert cli.main(argv) == 2, argv
    line = _one_line(capsys, said)
    assert len(line) < 400, line
  assert not (tmp_path / "o").exists()
  assert cli.main(["data", "convert", str(shared_data / BVH), "-o", str(tmp_path / "o"), "--joint-map", "m.toml"]) == 2
  _one_line(capsys, "m.toml: a joint map places the 16 training joints: give --joints mpii16 with it")


def test_like_on_a_take_without_extent_and_a_rate_that_would_resample_past_memory_are_one_line(tmp_path, capsys):
  from chorjax.data.dataset import bundled_path

  (tmp_path / "point.csv").write_text(("5," * 47 + "5\n") * 40)  # every joint at one point: no body to scale
  take = str(bundled_path("cmu94") / "94_01_skeleton_3d.csv")
  assert cli.main(["data", "convert", str(tmp_path / "point.csv"), "-o", str(tmp_path / "a"), "--like", "cmu94"]) == 2
  _one_line(capsys, "no extent", "point.csv")
  # a rate that would resample a take past memory is refused before anything is read: rates are 1-1000
  with pytest.raises(SystemExit) as e:
    cli.main(["data", "convert", take, "-o", str(tmp_path / "b"), "--fps", "0.000001", "--like", "cmu94"])
  assert e.value.code == 2
  _one_line(capsys, "--fps", "from 1 to 1000")
  assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_a_list_of_seeds_too_long_or_too_large_to_train_together_is_one_line(tmp_path, capsys):
  """train.seed=[0, ..., 19999] built 20,000 configs before anything said no (minutes); it is refused at once,
  and a list whose models together exceed memory is refused before any is built."""
  for count, said in ((20_000, "train.seed: 20,000 points; at most 1,024"), (1_000, "x 1,000 points trained together")):
    seeds = f"train.seed={list(range(count))}"
    wide = "model.hidden_size=2048"  # 1.3 GB a model to train: a thousand of them fit no machine
    assert cli.main(["train", QUICKSTART, seeds, wide, "--workdir", str(tmp_path / "w")]) == 2
    _one_line(capsys, said)
  assert not (tmp_path / "w").exists()


def test_a_checkpoint_whose_meta_no_longer_fits_its_parameters_is_one_line(tmp_path, capsys):
  """A hand-edited meta (hidden 16 -> 24) once surfaced as orbax's ValueError; it is a UserError naming the
  file and what does not fit, from the API as from the command line."""
  import chorjax

  run = tmp_path / "run"
  train_and_evaluate(tiny_config("log.tensorboard=false"), run)
  meta = next(run.glob("checkpoints/*/meta/metadata"))
  meta.write_text(meta.read_text().replace('"hidden_size": 16', '"hidden_size": 24'))
  with pytest.raises(UserError, match=r"metadata|params.*do not fit the model its meta describes"):
    chorjax.load_run(run)
  assert cli.main(["sample", str(run), "-o", str(tmp_path / "s.csv")]) == 2
  _one_line(capsys, "damaged checkpoint (its parameters do not fit the model its meta describes")
  assert not (tmp_path / "s.csv").exists()
  # arrays of another size than the meta's (3 -> 2 components): orbax's reads end in errors that Python printed
  # after the refusal, 130-323 lines of "Exception ignored in: <coroutine ...>", at the process's end
  meta.write_text(
    meta.read_text().replace('"hidden_size": 24', '"hidden_size": 16').replace('"num_mixtures": 3', '"num_mixtures": 2')
  )
  argv = ["-m", "chorjax.cli", "sample", str(run), "-o", str(tmp_path / "s.csv")]
  done = subprocess.run([sys.executable, *argv], capture_output=True, text=True, timeout=300)
  assert done.returncode == 2 and done.stderr.count("\n") == 1 and "do not fit the model" in done.stderr, done.stderr


def test_an_end_sample_too_large_for_memory_is_refused_before_training(tmp_path, capsys):
  """sample.frames=10**9 trained, then aborted natively (a failed XLA check) while drawing the end sample."""
  assert cli.main(["train", QUICKSTART, "sample.frames=1000000000", "--workdir", str(tmp_path / "w")]) == 2
  _one_line(capsys, "sample.frames=1000000000: needs about")
  assert not (tmp_path / "w").exists()


def test_a_file_too_large_to_read_whole_is_refused_before_it_is_read(monkeypatch, capsys):
  """Readers take a file whole: one larger than memory allows (here, a machine of 100 kB) is named first."""
  import chorjax.errors
  from chorjax.data.dataset import bundled_path

  monkeypatch.setattr(chorjax.errors, "memory_bytes", lambda: 100_000)
  take = bundled_path("cmu94") / "94_01_skeleton_3d.csv"
  assert cli.main(["data", "info", str(take)]) == 2
  _one_line(capsys, "94_01_skeleton_3d.csv: a 395,435-byte CSV file, read whole: needs about")


def test_an_error_quoting_a_name_with_a_line_break_stays_one_line(tmp_path, capsys):
  """A file name may hold a newline or a terminal escape; the one-line error writes them as escapes."""
  assert cli.main(["data", "info", str(tmp_path / "take\n\x1b[31mred.csv")]) == 2
  line = _one_line(capsys, "take\\n\\x1b[31mred.csv")
  assert "\x1b" not in line


def test_saved_state_nested_too_deep_is_one_line(tmp_path, capsys):
  """calibration.json, an evaluation's metrics.json, an NPZ's meta and a live message nested 5,000 deep were
  RecursionErrors; each is its reader's one-line error."""
  import asyncio

  from chorjax.data.dataset import bundled_path
  from chorjax.live.server import Live

  deep = "[" * 5000 + "]" * 5000
  w = tmp_path / "run"
  train_and_evaluate(tiny_config("log.tensorboard=false"), w)
  (w / "calibration.json").write_text(deep)
  assert cli.main(["sample", str(w), "-o", str(tmp_path / "s.csv"), "--frames", "10"]) == 2
  _one_line(capsys, "calibration.json")
  (w / "calibration.json").unlink()
  (w / "eval").mkdir()
  (w / "eval" / "metrics.json").write_text(deep)
  assert cli.main(["compare", str(w), "-o", str(tmp_path / "r.md")]) == 2
  _one_line(capsys, "metrics.json: damaged evaluation (not JSON: nested too deeply")
  import chorjax

  chorjax.read_motion(str(bundled_path("cmu94") / "94_01_skeleton_3d.csv")).write(tmp_path / "t.npz")
  positions = np.load(tmp_path / "t.npz")["positions"]
  np.savez(tmp_path / "deep.npz", positions=positions, meta=np.array(deep))
  assert cli.main(["data", "info", str(tmp_path / "deep.npz")]) == 2
  _one_line(capsys, "deep.npz: not a chorjax sample .npz (JSONDecodeError)")
  reply = json.loads(asyncio.run(Live.handle(None, deep)))  # type: ignore[arg-type]  (refused before self is used)
  assert "nested too deeply" in reply["error"]


def test_a_one_element_list_of_seeds_is_that_seed_checked_as_the_seed_alone(tmp_path, capsys):
  """``train.seed=[5]`` trained seed 0 and recorded 0; ``[-1]``, ``["a"]``, ``[1.5]``, ``[true]`` trained seed 0
  too. A one-element list is its value: trained and recorded, or refused in one line as the scalar is."""
  (tmp_path / "base.toml").write_text("")  # the defaults
  args = ["train", str(tmp_path / "base.toml"), *TINY, "log.tensorboard=false", "train.calibrate=false"]
  assert cli.main([*args, "train.seed=[5]", "--workdir", str(tmp_path / "w")]) == 0
  assert json.loads((tmp_path / "w" / "config.json").read_text())["train"]["seed"] == 5
  for bad in ("[-1]", '["a"]', "[1.5]", "[true]"):
    assert cli.main([*args, f"train.seed={bad}", "--workdir", str(tmp_path / "x")]) == 2, bad
    _one_line(capsys, "train.seed")
  assert not (tmp_path / "x").exists()


def test_a_step_count_past_the_32_bit_counter_is_refused_before_anything_is_written(tmp_path, capsys):
  """``train.epochs=1e9`` became 43,750,000,000 steps and ``1e300`` a 301-digit count (the step counter is
  int32); they, and such a ``train.num_steps``, are one line naming the key, exit 2, no workdir."""
  (tmp_path / "base.toml").write_text("")
  args = ["train", str(tmp_path / "base.toml"), *TINY, "log.tensorboard=false", "--workdir", str(tmp_path / "w")]
  for bad, key in (("train.epochs=1e9", "train.epochs"), ("train.epochs=1e300", "train.epochs")):
    assert cli.main([*args, bad]) == 2, bad
    _one_line(capsys, key)
  assert cli.main([*args, "train.num_steps=3000000000"]) == 2
  _one_line(capsys, "train.num_steps")
  assert not (tmp_path / "w").exists()


def test_an_empty_cache_path_is_refused_not_the_working_directory(tmp_path, capsys, monkeypatch):
  """``data.cache=""`` was the working directory: cache entries among the user's files. It is one line."""
  monkeypatch.chdir(tmp_path)
  (tmp_path / "base.toml").write_text("")
  for empty in ('data.cache=""', "data.cache=' '"):
    assert cli.main(["train", "base.toml", *TINY, empty, "--workdir", "w"]) == 2
    _one_line(capsys, "data.cache")
  assert sorted(p.name for p in tmp_path.iterdir()) == ["base.toml"]


def test_data_convert_to_a_file_name_it_cannot_write_is_refused_not_a_folder(tmp_path, capsys):
  """``data convert X -o conv.glb`` made a folder named conv.glb holding a CSV; a name that says another
  format is one line now, and nothing is made."""
  from chorjax.data.dataset import bundled_path

  take = str(bundled_path("cmu94") / "94_01_skeleton_3d.csv")
  for name in ("conv.glb", "conv.HTML", "conv.mp4"):
    assert cli.main(["data", "convert", take, "-o", str(tmp_path / name)]) == 2, name
    _one_line(capsys, name)
  assert not list(tmp_path.iterdir())
  assert cli.main(["data", "convert", take, "-o", str(tmp_path / "takes.v2")]) == 0  # a folder with a dot
  assert (tmp_path / "takes.v2" / "94_01_skeleton_3d.csv").is_file()


def test_several_seeds_do_not_write_into_a_seeds_folder_of_the_users_files(tmp_path, capsys):
  """``train.seed=[0,1] --workdir DIR`` replaced ``DIR/seed=1/samples/sample.csv`` the user had put there (a
  single run refuses a folder that is not a run; the per-seed folders were not checked). Now refused, one line,
  nothing written, the file as it was."""
  (tmp_path / "base.toml").write_text("")
  mine = tmp_path / "w" / "seed=1" / "samples" / "sample.csv"
  mine.parent.mkdir(parents=True)
  mine.write_text("my own\n")
  args = ["train", str(tmp_path / "base.toml"), *TINY, "log.tensorboard=false", "train.seed=[0, 1]"]
  assert cli.main([*args, "--workdir", str(tmp_path / "w")]) == 2
  _one_line(capsys, "seed=1")
  assert mine.read_text() == "my own\n" and sorted(p.name for p in (tmp_path / "w").iterdir()) == ["seed=1"]
  assert sorted(p.name for p in (tmp_path / "w" / "seed=1").iterdir()) == ["samples"]


def test_data_convert_keeps_a_skeleton_sidecar_the_user_had(shared_data, tmp_path, capsys):
  """``data convert t.bvh -o out/`` rewrote the user's ``out/t.skeleton.json`` when ``out/t.csv`` did not exist
  yet: the sidecar is an output too, refused unless ``--force``, and nothing is written."""
  take = shared_data / "bvh" / "cmu131" / "131_01.bvh"
  mine = tmp_path / "out" / "131_01.skeleton.json"
  mine.parent.mkdir()
  mine.write_text("my own\n")
  assert cli.main(["data", "convert", str(take), "-o", str(tmp_path / "out")]) == 2
  _one_line(capsys, "131_01.skeleton.json")
  assert mine.read_text() == "my own\n" and sorted(p.name for p in mine.parent.iterdir()) == [mine.name]
  assert cli.main(["data", "convert", str(take), "-o", str(tmp_path / "out"), "--force"]) == 0
  assert (tmp_path / "out" / "131_01.csv").is_file() and mine.read_text() != "my own\n"


def test_a_pattern_that_backtracks_without_end_is_refused_not_run_forever(tmp_path, capsys):
  """``data.labels = '^(?P<x>(a+)+)$'`` (or ``data.val_pattern``) on a take named ``aaaa...a!`` ran until killed,
  leaving a workdir with only ``.lock``. Matching a take's name now has a second: then one line, nothing left."""
  import shutil

  from chorjax.data.dataset import bundled_path

  data = tmp_path / "takes"
  data.mkdir()
  for name in ("a" * 40 + "!", "aa"):
    shutil.copy(bundled_path("cmu94") / "94_01_skeleton_3d.csv", data / f"{name}.csv")
  (tmp_path / "base.toml").write_text("")
  args = ["train", str(tmp_path / "base.toml"), *TINY, f"data.dataset={str(data)!r}", "--workdir", str(tmp_path / "w")]
  # the regex package sees through (a+)+ (the take is then said not to match); (a|aa)+ it cannot
  cases = [("data.labels", "^(?P<x>(a+)+)$", "does not match"), ("data.labels", "^(?P<x>(a|aa)+)$", "simplify the")]
  cases.append(("data.val_pattern", "^(a|aa)+$", "simplify the pattern"))
  for key, pattern, said in cases:
    assert cli.main([*args, f"{key}='{pattern}'"]) == 2
    _one_line(capsys, key, said)
    assert not (tmp_path / "w").exists()


@pytest.mark.parametrize("suffix", [".csv", ".npz", ".bvh", ".glb", ".html"])
def test_motion_write_refuses_nan_frames_and_empty_motions_in_one_line(tmp_path, suffix):
  """``Motion.write`` of a NaN frame to ``.glb`` was a LinAlgError, of 0 frames to ``.glb``/``.bvh`` an
  IndexError, and NaN went silently into ``.csv``, ``.npz`` and ``.bvh``: now one UserError, nothing written."""
  from chorjax import read_motion
  from chorjax.data.dataset import bundled_path
  from chorjax.errors import UserError

  take = read_motion(bundled_path("cmu94") / "94_01_skeleton_3d.csv")
  nan = take.positions[:20].copy()
  nan[7, 3, 1] = np.nan
  for positions, said in ((nan, "frame 7 holds NaN"), (take.positions[:0], "no frames")):
    with pytest.raises(UserError, match=said):
      take.replace(positions=positions).write(tmp_path / f"m{suffix}")
  assert not list(tmp_path.iterdir())
  assert take.replace(positions=take.positions[:20]).write(tmp_path / f"m{suffix}").is_file()


def test_a_batch_that_xla_cannot_hold_or_too_many_shares_are_refused_before_training(tmp_path, capsys):
  """``train.batch_size=100000`` on a small model passed the memory check (11.8 GiB), then XLA asked for 24.5 GB
  (an internal error); ``train.batch_parts=100000`` made LLVM abort (exit 134). Both one line now, nothing made."""
  (tmp_path / "base.toml").write_text("")
  args = ["train", str(tmp_path / "base.toml"), *TINY, "--workdir", str(tmp_path / "w")]
  assert cli.main([*args, "train.batch_size=100000"]) == 2
  _one_line(capsys, "train.batch_size=100000", "GiB")
  assert cli.main([*args, "train.batch_size=100000", "train.batch_parts=100000"]) == 2
  _one_line(capsys, "train.batch_parts")
  assert not (tmp_path / "w").exists()


def test_a_cache_entry_that_is_not_a_file_is_made_again_not_read(tmp_path, capsys):
  """Cache entries replaced by FIFOs blocked training forever (reading one waits for a writer). An entry that
  is not a regular file is never opened: the take is read again and the entry written over it."""
  import threading

  from chorjax.data.cache import Cache
  from chorjax.data.csv import read_csv as read
  from chorjax.data.dataset import bundled_path

  take = bundled_path("cmu94") / "94_01_skeleton_3d.csv"
  cache = Cache(tmp_path / "cache")
  first = cache.motions(take, {"v": 1}, lambda: [read(take)])
  entry = next((tmp_path / "cache").rglob("*.npz"))
  entry.unlink()
  os.mkfifo(entry)
  got: list = []
  worker = threading.Thread(target=lambda: got.append(cache.motions(take, {"v": 1}, lambda: [read(take)])), daemon=True)
  worker.start()
  worker.join(timeout=60)
  assert got, "reading the cache blocked on a FIFO"
  np.testing.assert_array_equal(got[0][0].positions, first[0].positions)
  assert "is not a file" in capsys.readouterr().err and entry.is_file()


def test_a_cache_entry_holding_another_takes_arrays_is_encoded_again(tmp_path, capsys):
  """A features entry holding another take's arrays under the right key (its own key written in) trained on
  the wrong take. What an entry holds is checked against the take's positions: made again, and said."""
  from chorjax.config import load_config
  from chorjax.data.dataset import load_dataset

  cfg = load_config(None, ["data.dataset=cmu94", f"data.cache={tmp_path / 'cache'}", "data.representation=canonical"])
  first = load_dataset(cfg.data)
  entries = sorted((tmp_path / "cache" / "features").rglob("*.npz"), key=lambda p: p.stat().st_size)
  small, large = entries[0], entries[-1]
  with np.load(large) as other:
    swapped = {k: other[k] for k in other.files if k != "__key__"}
  with np.load(small) as mine:
    key = str(mine["__key__"])
  with open(small, "wb") as f:
    np.savez(f, __key__=np.array(key), **swapped)
  capsys.readouterr()
  again = load_dataset(cfg.data)
  assert "holds another take's arrays" in capsys.readouterr().err
  for (_, a), (_, b) in zip(first.train, again.train, strict=True):
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize(
  "args, flag",
  [
    (["render", "cmu94/94_01_skeleton_3d.csv", "-o", "{tmp}/x.gif", "--fps", "1e-9"], "--fps"),
    (["data", "convert", "cmu94/94_01_skeleton_3d.csv", "-o", "{tmp}/c", "--fps", "0.5"], "--fps"),
    (["data", "convert", "cmu94/94_01_skeleton_3d.csv", "-o", "{tmp}/c", "--amc-fps", "0.001"], "--amc-fps"),
    (["calibrate", "{tmp}", "--seed", "18446744073709551617"], "--seed"),
    (["calibrate", "{tmp}", "--seed", "-1"], "--seed"),
    (["eval", "{tmp}", "--seeds", "-1"], "--seeds"),
    (["metrics", "cmu94/94_01_skeleton_3d.csv", "--data", "cmu94", "--seed", "-1"], "--seed"),
    (["data", "convert", "cmu94/94_01_skeleton_3d.csv", "-o", "{tmp}/c", "--scale", "1e-45"], "--scale"),
    (["data", "convert", "cmu94/94_01_skeleton_3d.csv", "-o", ""], "-o '': an empty path"),
    (["sample", "", "-o", "{tmp}/s.csv"], "WORKDIR '': an empty path"),
    (["calibrate", "{tmp}", "--pace", "1e308"], "--pace"),
  ],
)
def test_rates_and_seeds_out_of_range_are_one_line(tmp_path, capsys, args, flag):
  """``render --fps 1e-9`` and ``calibrate --seed 18446744073709551617`` were internal errors; ``data convert --fps
  0.5`` (documented 1-1000), ``--amc-fps 0.001``, ``--scale 1e-45`` (a body of size 0), ``-o ''`` (the working
  directory), ``calibrate --seed -1``, ``--pace 1e308`` and ``eval --seeds -1`` passed."""
  from chorjax.data.dataset import bundled_path

  take = str(bundled_path("cmu94").parent)
  argv = [a.replace("{tmp}", str(tmp_path)).replace("cmu94/", take + "/cmu94/") for a in args]
  try:
    code = cli.main(argv)
  except SystemExit as e:
    code = e.code
  assert code == 2
  _one_line(capsys, flag)
  assert not list(tmp_path.iterdir())


def test_dropping_the_only_frame_of_a_take_is_one_line(shared_data, tmp_path, capsys):
  """``data convert --drop-first-frame`` of a one-frame BVH was an internal error."""
  lines = (shared_data / BVH).read_text().splitlines()
  at = next(i for i, line in enumerate(lines) if line.startswith("Frames:"))
  one = tmp_path / "one.bvh"
  one.write_text("\n".join([*lines[:at], "Frames: 1", lines[at + 1], lines[at + 2]]) + "\n")
  assert cli.main(["data", "convert", str(one), "-o", str(tmp_path / "out"), "--drop-first-frame"]) == 2
  _one_line(capsys, "one.bvh: one frame")
  assert sorted(p.name for p in tmp_path.iterdir()) == ["one.bvh"]


def test_valid_input_that_was_refused_is_taken(shared_data, tmp_path, capsys):
  """A CSV named with 250 characters (its sidecar's name would be too long to look for) and ``--up-axis -x``
  (argparse took the axis for a flag) were refused."""
  from chorjax.data.dataset import bundled_path

  take = tmp_path / ("a" * 246 + ".csv")
  take.write_bytes((bundled_path("cmu94").parent / "cmu94" / "94_01_skeleton_3d.csv").read_bytes())
  assert cli.main(["render", str(take), "-o", str(tmp_path / "strip.png"), "--strip"]) == 0
  out = tmp_path / "native"
  argv = ["data", "convert", str(shared_data / BVH), "-o", str(out), "--joints", "native", "--up-axis", "-x"]
  assert cli.main([*argv, "--scale", "0.001"]) == 0
  assert "up -x" in capsys.readouterr().out and len(list(out.glob("*.csv"))) == 1


@pytest.mark.parametrize(
  "sizes",
  [
    ["model.hidden_size=32", "model.num_layers=1", "train.batch_size=512", "data.seq_length=12"],  # the head rules
    ["model.hidden_size=96", "model.num_layers=2", "train.batch_size=16", "data.seq_length=64"],
    ["model.hidden_size=128", "model.num_layers=3", "train.batch_size=8", "data.seq_length=100", "model.head=mse"],
  ],
)
def test_the_memory_estimate_covers_what_the_compiled_step_asks_for(sizes):
  """``train.batch_size=100000`` passed the memory check, then XLA asked for 24.5 GB. The estimate the check
  makes before anything is allocated (``config.training_bytes``) is compared with what XLA's compiled train
  step needs (its arguments, outputs and temporaries): never less, and within 4x."""
  import jax

  from chorjax.config import load_config, training_bytes
  from chorjax.data.dataset import load_dataset
  from chorjax.families import family_of
  from chorjax.families.recurrent.steps import train_step

  cfg = load_config(QUICKSTART, [*sizes, "train.batch_parts=1"])
  ds = load_dataset(cfg.data)
  state, spec = family_of(cfg).create_state(cfg, ds)
  _, sampler, _, _ = family_of(cfg).parts(cfg, ds)
  stats = train_step.lower(state, sampler.batch(0), jax.random.key(0), spec).compile().memory_analysis()
  needed = stats.argument_size_in_bytes + stats.output_size_in_bytes - stats.alias_size_in_bytes
  needed += stats.temp_size_in_bytes
  assert needed <= training_bytes(cfg) <= 4 * needed, (needed / 2**20, training_bytes(cfg) / 2**20)


def test_sidecars_and_amc_files_that_say_two_things_at_once_are_one_line(shared_data, tmp_path, capsys):
  """Read silently before, or an internal error: a sidecar naming one joint twice or giving its rate as
  text or a boolean, a sidecar that is a folder, an AMC frame number of 5,000 digits, an ASF bone under two
  parents."""
  import shutil

  convert = ["data", "convert", str(shared_data / BVH), "-o", str(tmp_path / "nat"), "--joints", "native"]
  assert cli.main(convert) == 0
  (csv,) = (tmp_path / "nat").glob("*.csv")
  side = csv.with_name(csv.stem + ".skeleton.json")
  good = json.loads(side.read_text())
  names = good["skeleton"]["joint_names"]
  for change, said in (
    ({"skeleton": {**good["skeleton"], "joint_names": [names[0], *names[:-1]]}}, "appears twice"),
    ({"fps": "30"}, "fps: expected a number, got '30'"),
    ({"fps": True}, "fps: expected a number, got True"),
  ):
    side.write_text(json.dumps({**good, **change}))
    assert cli.main(["data", "info", str(csv)]) == 2
    _one_line(capsys, side.name, said)
  side.unlink()
  side.mkdir()
  assert cli.main(["data", "info", str(csv)]) == 2
  _one_line(capsys, "not a file; a CSV's sidecar is the file NAME.skeleton.json")
  cmu05 = shared_data / "asfamc" / "cmu05"
  amc_dir = tmp_path / "amc"
  amc_dir.mkdir()
  (asf,) = cmu05.glob("*.asf")
  shutil.copy(asf, amc_dir / asf.name)
  lines = (cmu05 / "md_02.amc").read_text().splitlines()
  first = next(i for i, line in enumerate(lines) if line.strip().isdigit())
  (amc_dir / "big.amc").write_text("\n".join([*lines[:first], "9" * 5000, *lines[first + 1 :]]) + "\n")
  assert cli.main(["data", "info", str(amc_dir / "big.amc")]) == 2
  _one_line(capsys, "big.amc", "has 5000 digits")
  text = asf.read_text().replace("    rhipjoint rfemur\n", "    rhipjoint rfemur lfemur\n")
  assert "rfemur lfemur" in text
  (amc_dir / asf.name).write_text(text)
  assert cli.main(["data", "info", str(amc_dir / "big.amc")]) == 2
  _one_line(capsys, asf.name, "'lfemur' is a child of 'lhipjoint' already")


def test_a_reference_body_of_no_size_is_one_line(tmp_path, capsys):
  """``data convert --like`` a take whose joints all sit at one point scaled every take to nothing, silently."""
  from chorjax.data.dataset import bundled_path

  zero = tmp_path / "zero.csv"
  np.savetxt(zero, np.zeros((40, 48)), delimiter=",")
  take = bundled_path("cmu94") / "94_03_skeleton_3d.csv"
  assert cli.main(["data", "convert", str(take), "-o", str(tmp_path / "out"), "--like", str(zero)]) == 2
  _one_line(capsys, "--like", "no extent")
  assert not (tmp_path / "out").exists()


def test_a_chain_two_thousand_joints_deep_goes_to_bvh_and_back(tmp_path):
  """The BVH writer walked the hierarchy by recursion: a 2,000-joint chain was an internal error
  (RecursionError)."""
  import chorjax
  from chorjax.data.motion import Motion, Skeleton

  j = 2000
  sk = Skeleton("chain", tuple(f"j{i}" for i in range(j)), (-1, *range(j - 1)), tuple(range(j)))
  pos = np.zeros((5, j, 3), np.float32)
  pos[:, :, 1], pos[:, :, 0] = np.arange(j) * 0.01, np.sin(np.arange(j) / 50) * 0.1
  path = chorjax.Motion.of(Motion(pos, 30.0, sk)).write(tmp_path / "chain.bvh")
  back = chorjax.read_motion(str(path))
  order = [back.skeleton.joint_names.index(n) for n in sk.joint_names]
  assert np.abs(np.asarray(back.positions)[:, order] - pos).max() < 1e-4 * j * 0.01 * 10


def test_no_command_changes_a_file_it_did_not_write(tmp_path, capsys):
  """A folder of the user's files and a run itself, given as targets to export, train, sweep, data convert,
  sample, render and the API, with --force and without: what chorjax may do is refuse or add its own files;
  every file that was there keeps its bytes."""
  import chorjax
  from chorjax.data.dataset import bundled_path

  run, user = tmp_path / "run", tmp_path / "user"
  train_and_evaluate(tiny_config("log.tensorboard=false", "train.calibrate=false"), run)
  (user / "nested").mkdir(parents=True)
  (user / "a.txt").write_text("mine")
  (user / "b.csv").write_text("1,2,3\n")
  (user / "nested" / "c.bin").write_bytes(b"\x00\x01")
  before = {p: p.read_bytes() for p in [*run.rglob("*"), *user.rglob("*")] if p.is_file()}
  take = str(bundled_path("cmu94") / "94_03_skeleton_3d.csv")
  sweep = tmp_path / "s.toml"
  sweep.write_text(f'name = "s"\nbase = "{QUICKSTART}"\nroot = "{user}"\n[grid]\n"train.seed" = [0]\n')
  tiny = ["train.num_steps=1", "model.hidden_size=8", "model.num_layers=1", "log.tensorboard=false"]
  commands = [
    ["export", str(run), "--web", str(user)],
    ["export", str(run), "--web", str(user), "--force"],
    ["export", str(run), "--web", str(run), "--force"],
    ["train", QUICKSTART, *tiny, "--workdir", str(user)],
    ["data", "convert", take, "-o", str(run), "--force"],
    ["data", "convert", take, "-o", str(user), "--force"],
    ["sample", str(run), "-o", str(user / "b.csv"), "--frames", "10"],
    ["render", take, "-o", str(user / "a.txt")],
    ["sweep", str(sweep), *tiny],
  ]
  for argv in commands:
    with contextlib.suppress(SystemExit):
      cli.main(argv)
    capsys.readouterr()
  with pytest.raises(chorjax.UserError):
    chorjax.read_motion(take).write(user / "b.csv")
  changed = [str(p) for p, data in before.items() if not p.is_file() or p.read_bytes() != data]
  assert not changed, changed
  assert {p for p in run.rglob("*") if p.is_file()} == {p for p in before if run in p.parents}  # nothing added


def test_data_convert_never_writes_into_a_run_that_has_started(tmp_path, capsys):
  """A run folder is one with its config or its checkpoints (as training reads it): data convert refuses to
  write takes into one that holds only its config (a start that stopped before its first checkpoint)."""
  from chorjax.data.dataset import bundled_path

  started = tmp_path / "started"
  started.mkdir()
  (started / "config.json").write_text("{}")
  take = str(bundled_path("cmu94") / "94_03_skeleton_3d.csv")
  assert cli.main(["data", "convert", take, "-o", str(started), "--force"]) == 2
  assert "a chorjax run's folder" in capsys.readouterr().err
  assert [p.name for p in started.iterdir()] == ["config.json"]
