"""Own data end to end: native skeletons in CSV, stable BVH round trips, frame rates, the split warning."""

import json

import numpy as np
import pytest
from helpers import TINY, tiny_config

from chorjax import cli
from chorjax.data.bvh import read_bvh, write_bvh
from chorjax.data.csv import read_csv, sidecar_path
from chorjax.data.dataset import bundled_path, dataset_notes, load_dataset
from chorjax.errors import UserError
from chorjax.evaluation.scoring import mean_of
from chorjax.run import load_run


def test_bvh_round_trips_add_no_joints(shared_data, tmp_path):
  first = read_bvh(shared_data / "bvh" / "cmu131" / "131_01.bvh")
  m = first
  for k in range(2):
    m = read_bvh(write_bvh(m, tmp_path / f"{k}.bvh"))
    assert m.skeleton.joint_names == first.skeleton.joint_names
    assert m.skeleton.parents == first.skeleton.parents
    np.testing.assert_allclose(m.positions, first.positions, atol=1e-3 * np.ptp(first.positions[..., 1]))


def test_a_native_csv_trains_on_its_own_skeleton(shared_data, tmp_path, capsys):
  takes = [shared_data / "bvh" / "cmu131" / f"131_0{k}.bvh" for k in (1, 2)]
  out = tmp_path / "native"
  assert cli.main(["data", "convert", *map(str, takes), "-o", str(out), "--joints", "native"]) == 0
  side = json.loads(sidecar_path(out / "131_01.csv").read_text())
  assert side["fps"] == 120.0 and len(side["skeleton"]["joint_names"]) == 38
  back = read_csv(out / "131_01.csv")  # the sidecar decides skeleton, rate and up axis
  assert back.skeleton.joint_names == read_bvh(takes[0]).skeleton.joint_names and back.fps == 120.0
  assert back.up_axis == "y"
  capsys.readouterr()
  args = [*TINY, f"data.dataset={out}", "data.joints=native", "data.resample_fps=30"]
  (tmp_path / "defaults.toml").write_text("")
  assert cli.main(["train", str(tmp_path / "defaults.toml"), *args, "--workdir", str(tmp_path / "run")]) == 0
  said = capsys.readouterr().out
  assert "a training window of 12 frames lasts 0.4 s at 30 fps" in said
  # the run is named by its folder (its config says "default"), in the log and in the player's title
  assert (
    "trained run: " in said
    and "<title>chorjax: run</title>" in (tmp_path / "run" / "samples" / "player.html").read_text()
  )
  run = load_run(tmp_path / "run")
  assert run.fps == 30.0 and run.features.skeleton.num_joints == 38
  # the same CSVs mapped onto the 16 joints by their sidecar's names
  ds = load_dataset(tiny_config(f"data.dataset={out}").data)
  assert ds.mappings["131_01"].method == "names" and ds.fps == 120.0


def test_data_skeleton_names_a_skeleton_file(shared_data, tmp_path):
  take = shared_data / "bvh" / "bvh_python" / "test_mocapbank.bvh"
  assert cli.main(["data", "convert", str(take), "-o", str(tmp_path / "a"), "--joints", "native"]) == 0
  plain = tmp_path / "b"
  plain.mkdir()
  (plain / "take.csv").write_text((tmp_path / "a" / "test_mocapbank.csv").read_text())
  with pytest.raises(UserError, match=r"take.csv:1: expected 48 columns"):
    load_dataset(tiny_config(f"data.dataset={plain}").data)
  sk = str(sidecar_path(tmp_path / "a" / "test_mocapbank.csv"))
  ds = load_dataset(tiny_config(f"data.dataset={plain}", f"data.skeleton={sk}", "data.fps=30").data)
  assert ds.motions[0].num_frames == 455 and ds.mappings["take"].method == "names"
  with pytest.raises(UserError, match=r"data.skeleton: nope.skeleton.json: no such skeleton file"):
    load_dataset(tiny_config(f"data.dataset={plain}", "data.skeleton=nope.skeleton.json").data)


def test_mixed_frame_rates_are_resampled_with_a_note(shared_data, tmp_path):
  folder = tmp_path / "mixed"
  folder.mkdir()
  for src in (
    shared_data / "bvh" / "cmu131" / "131_01.bvh",
    shared_data / "bvh" / "bandai" / "dataset-1_dance-short_normal_001.bvh",
  ):
    (folder / src.name).write_bytes(src.read_bytes())
  ds = load_dataset(tiny_config(f"data.dataset={folder}").data)
  assert ds.fps == 120.0 and {m.fps for m in ds.motions} == {120.0}
  assert ds.motions[1].num_frames == (1901 - 1) * 4 + 1  # the 30 fps dance, 4 frames for each
  notes = dataset_notes(ds)
  assert any("mixed frame rates (1 at 30 fps, 1 at 120 fps): resampled to 120 fps" in n for n in notes)
  ds = load_dataset(tiny_config(f"data.dataset={folder}", "data.resample_fps=30").data)
  assert ds.fps == 30.0 and ds.motions[0].num_frames == (994 - 1) // 4 + 1
  assert not any("mixed" in n for n in dataset_notes(ds))


def test_a_single_take_warns_that_nothing_is_held_out(shared_data):
  ds = load_dataset(tiny_config(f"data.dataset={shared_data / 'bvh' / 'cmu131' / '131_01.bvh'}").data)
  assert ds.val_names == ()
  assert any(n.startswith("warning: no validation split (a single take)") for n in dataset_notes(ds))
  assert not any("validation" in n for n in dataset_notes(load_dataset(tiny_config().data)))


# every file in ../shared/data: (up axis, units) as its README and sources say
KNOWN = {
  "cmu94": ("-y", "arbitrary"),
  "asfamc/cmu131": ("y", "cmu_asf"),
  "asfamc/cmu05": ("y", "cmu_asf"),
  "bvh/cmu131": ("y", "cmu_asf"),
  "bvh/bandai": ("y", "cm"),
  "bvh/bvh_python": ("y", "cm"),
  "bvh/pymo": ("y", "in"),
  "c3d/cmu01": ("z", "mm"),
  "c3d/ezc3d": ("z", "mm"),
}


def test_data_check_knows_units_and_up_axis_of_every_shared_file(shared_data):
  from chorjax.data.check import check_paths

  seen = 0
  for folder, (up, units) in KNOWN.items():
    reports, config = check_paths([str(shared_data / folder)])
    for r in reports:
      if "Optotrak" in r.path:  # truncated: refused, one line
        assert r.fatal and "truncated" in r.fatal[0]
        continue
      seen += 1
      want = "m" if "scaled_" in r.path else units  # the bvh11 copy scaled to metres
      assert (r.up_axis, r.units) == (up, want), (r.path, r.up_evidence, r.units_evidence)
      assert not r.fatal
    assert f"data.up_axis = {up!r}" in config
  assert seen == 10 + 4 + 5 + 4 + 3 + 2 + 1 + 1 + 1


def test_data_check_command_reports_and_fails_on_fatal_problems(shared_data, tmp_path, capsys):
  assert cli.main(["data", "check", str(shared_data / "bvh" / "bandai")]) == 0
  out = capsys.readouterr().out
  assert "units cm: leg (hip-knee-ankle) 80.07 = 0.80 m in cm" in out
  assert "data.scale = 0.01" in out and 'data.joints = "mpii16"  # mapped names' in out
  assert "3 of 3 takes readable: 1952 frames" in out
  bad = tmp_path / "bad.csv"
  bad.write_text("1,2,3\n")
  code = cli.main(["data", "check", str(shared_data / "c3d" / "ezc3d"), str(bad)])
  err = capsys.readouterr().err.strip().splitlines()
  assert code == 2 and len(err) == 2
  assert "Optotrak.c3d: header declares 1149 frames" in err[0] and "bad.csv:1: expected 48 columns" in err[1]


def test_the_one_take_recipe_trains_on_one_bvh_csv_or_amc_file_and_refuses_a_take_too_short(
  shared_data, tmp_path, capsys
):
  """``chorjax train configs/one_take.toml data.dataset=FILE``, as a user runs it on one recording: each format
  trains, validating on the take's own last tenth, and ``eval --data held-out`` judges it on that tenth; a take
  too short for that is one line naming the file, and no run is started."""
  tiny = [t for t in TINY if not t.startswith("data.seq_length")] + ["data.seq_length=32", "log.tensorboard=false"]
  takes = [
    shared_data / "bvh" / "cmu131" / "131_01.bvh",
    shared_data / "asfamc" / "cmu05" / "md_02.amc",
    bundled_path("cmu94") / "94_03_skeleton_3d.csv",
  ]
  for k, take in enumerate(takes):
    work = tmp_path / f"run{k}"
    args = ["train", "configs/one_take.toml", f"data.dataset={take}", *tiny, "train.calibrate=false"]
    assert cli.main([*args, "--workdir", str(work)]) == 0, take
    run = load_run(work)
    assert run.config.data.val_tail == 0.1 and run.fps == 30.0
    assert [json.loads(line) for line in (work / "metrics.jsonl").read_text().splitlines() if "val_loss" in line]
  # judged on its held-out tail (82 frames): too short for a distribution, the rest is measured, with a note
  out = tmp_path / "tail.json"
  assert cli.main(["eval", str(work), "--data", "held-out", "--frames", "300", "--num", "1", "-o", str(out)]) == 0
  tail = json.loads(out.read_text())
  assert tail["fid_g"] is None and tail["fid_k"] is None and "too few 60-frame windows" in tail["fid_note"]
  assert mean_of(tail["jitter"]) > 0 and tail["coverage"] is not None  # the coverage: against the take it learned
  assert "note: FIDs and diversities not measured" in capsys.readouterr().out
  short = tmp_path / "short.csv"
  short.write_text("\n".join(takes[2].read_text().splitlines()[:100]) + "\n")  # 3.3 s
  assert cli.main(["train", "configs/one_take.toml", f"data.dataset={short}", "--workdir", str(tmp_path / "s")]) == 2
  err = capsys.readouterr().err
  assert err.count("\n") == 1 and "short.csv: 100 frames; data.val_tail = 0.1 needs at least" in err
  assert not (tmp_path / "s").exists()
