"""Real mocap formats from ../shared/data: BVH, ASF/AMC and C3D in; BVH out by inverse kinematics."""

import re

import numpy as np
import pytest
from helpers import tiny_config

from chorjax import cli
from chorjax.data.amc import read_amc
from chorjax.data.bvh import read_bvh, write_bvh
from chorjax.data.c3d import read_c3d
from chorjax.data.csv import read_csv
from chorjax.data.dataset import bundled_path, load_dataset, read_motions, resolve_files
from chorjax.data.mapping import to_mpii16
from chorjax.data.skeletons import MPII16
from chorjax.errors import UserError


def height(m):
  return float(np.ptp(m.positions[..., 1]))


def test_every_bvh_parses_with_header_frames_and_rate(shared_data):
  files = sorted((shared_data / "bvh").rglob("*.bvh"))
  assert len(files) == 10
  for f in files:
    text = f.read_text(errors="replace")
    frames = int(re.search(r"Frames:\s*(\d+)", text).group(1))
    frame_time = float(re.search(r"Frame Time:\s*([\d.]+)", text).group(1))
    m = read_bvh(f)
    assert m.num_frames == frames, f
    assert m.fps == pytest.approx(1 / frame_time, rel=1e-3), f
    assert np.isfinite(m.positions).all()
    ends = re.findall(r"End Site\s*\{\s*OFFSET\s+(\S+)\s+(\S+)\s+(\S+)", text)
    nonzero = sum(any(float(v) for v in e) for e in ends)  # a zero End Site sits on its joint: not a joint
    joints = len(re.findall(r"\b(?:ROOT|JOINT)\s", text)) + nonzero
    assert m.skeleton.num_joints == joints, f


def test_every_amc_parses_with_its_asf(shared_data):
  files = sorted((shared_data / "asfamc").rglob("*.amc"))
  assert len(files) == 9
  for f in files:
    frames = sum(1 for line in f.read_text().splitlines() if line.strip().isdigit())
    m = read_amc(f)
    assert m.num_frames == frames and m.fps == 120.0 and m.skeleton.num_joints == 31
    assert np.median(m.bone_lengths().std(0)) < 1e-4  # rigid bones by construction


@pytest.mark.parametrize("take", ["131_01", "131_02", "131_03"])
def test_asf_amc_and_bvh_give_the_same_positions(shared_data, take):
  a = read_amc(shared_data / "asfamc" / "cmu131" / f"{take}.amc")
  b = read_bvh(shared_data / "bvh" / "cmu131" / f"{take}.bvh")
  assert a.num_frames == b.num_frames
  ai = {n: i for i, n in enumerate(a.skeleton.joint_names)}
  bi = {n: i for i, n in enumerate(b.skeleton.joint_names)}
  tol = 1e-3 * height(b)
  # joints at the same place in both files (BVH joint <- the ASF bone ending there)
  same = {
    "Hips": "root",
    "LeftHip": "lhipjoint",
    "LeftKnee": "lfemur",
    "LeftAnkle": "ltibia",
    "LeftToe": "lfoot",
    "LeftToe_end": "ltoes",
    "RightHip": "rhipjoint",
    "RightKnee": "rfemur",
    "RightAnkle": "rtibia",
    "RightToe": "rfoot",
    "RightToe_end": "rtoes",
    "Chest": "lowerback",
    "Chest2": "upperback",
  }
  for bn, an in same.items():
    assert np.abs(a.positions[:, ai[an]] - b.positions[:, bi[bn]]).max() < tol, (bn, an)
  # this BVH conversion leaves out the ASF 'thorax' bone (1.98 units), so above it compare bone vectors
  for (b1, b0), (a1, a0) in [
    (("LeftElbow", "LeftShoulder"), ("lhumerus", "lclavicle")),
    (("LeftWrist", "LeftElbow"), ("lradius", "lhumerus")),
    (("RightElbow", "RightShoulder"), ("rhumerus", "rclavicle")),
    (("RightWrist", "RightElbow"), ("rradius", "rhumerus")),
    (("Head_end", "Head"), ("head", "upperneck")),
  ]:
    vb = b.positions[:, bi[b1]] - b.positions[:, bi[b0]]
    va = a.positions[:, ai[a1]] - a.positions[:, ai[a0]]
    assert np.abs(va - vb).max() < tol, (b1, b0)


def test_c3d_rates_frames_markers_and_the_truncated_file(shared_data, capsys):
  cmu = read_c3d(shared_data / "c3d" / "cmu01" / "01_01.c3d")
  assert (cmu.fps, cmu.num_frames, cmu.skeleton.num_joints, cmu.units) == (120.0, 2751, 42, "mm")
  q = read_c3d(shared_data / "c3d" / "ezc3d" / "Qualisys.c3d")
  assert (q.fps, q.num_frames, q.skeleton.num_joints) == (200.0, 340, 55)
  opto = shared_data / "c3d" / "ezc3d" / "Optotrak.c3d"
  with pytest.raises(UserError, match=r"Optotrak\.c3d: header declares 1149 frames .* holds 29"):
    read_c3d(opto)
  assert cli.main(["data", "info", str(opto)]) == 2
  assert "truncated" in capsys.readouterr().err


# ---------------------------------------------------------------- BVH out


@pytest.mark.parametrize("path", resolve_files("cmu94"), ids=lambda p: p.stem[:5])
def test_bvh_round_trip_of_the_cmu94_takes(tmp_path, path):
  m = read_csv(path)
  back = read_bvh(write_bvh(m, tmp_path / "t.bvh"))
  idx = [back.skeleton.joint_names.index(n) for n in m.skeleton.joint_names]
  assert np.abs(back.positions[:, idx] - m.positions).max() < 1e-3 * height(m)
  assert back.fps == pytest.approx(m.fps)


def test_rigid_bvh_keeps_bone_directions_with_constant_lengths(tmp_path):
  m = read_csv(resolve_files("cmu94")[4])
  back = read_bvh(write_bvh(m, tmp_path / "r.bvh", exact=False))
  idx = {n: i for i, n in enumerate(back.skeleton.joint_names)}
  for p, c in m.skeleton.bones:
    name = m.skeleton.joint_names
    child = idx.get(name[c], idx.get(f"{name[p]}_end"))
    got = back.positions[:, child] - back.positions[:, idx[name[p]]]
    want = m.positions[:, c] - m.positions[:, p]
    cos = np.sum(got * want, -1) / np.linalg.norm(got, axis=-1) / np.linalg.norm(want, axis=-1)
    if m.skeleton.parents.count(p) == 1:
      assert cos.min() > 0.9999, name[c]  # one child: the direction is kept exactly (swing)
    else:  # pelvis/thorax: a rigid triangle best-fit (Kabsch) to a non-rigid marker triangle
      assert cos.mean() > 0.995 and cos.min() > 0.98, name[c]  # a few degrees: shoulders wobble up to 7%
    assert np.linalg.norm(got, axis=-1).std() < 1e-3 * np.linalg.norm(got, axis=-1).mean()  # rigid


def test_written_bvh_reads_with_an_independent_reader(tmp_path):
  from bvh import Bvh

  m = read_csv(resolve_files("cmu94")[0])
  for exact in (True, False):
    text = write_bvh(m, tmp_path / f"{exact}.bvh", exact=exact).read_text()
    other = Bvh(text)
    assert other.nframes == m.num_frames and other.frame_time == pytest.approx(1 / 30, rel=1e-6)
    joints = 16 if exact else 16 - len([j for j in range(16) if j not in m.skeleton.parents])  # leaves -> End Site
    assert len(other.get_joints_names()) == joints


def test_generated_sample_exports_to_bvh(tmp_path, shared_data):
  from test_retarget import check_retargeted

  from chorjax.training.driver import train_and_evaluate

  train_and_evaluate(tiny_config("train.num_steps=2", "log.tensorboard=false"), tmp_path / "run")
  args = ["sample", str(tmp_path / "run"), "--frames", "120", "--seed", "3"]
  assert cli.main([*args, "-o", str(tmp_path / "s.csv")]) == 0
  assert cli.main([*args, "-o", str(tmp_path / "s.bvh")]) == 0
  csv, bvh = read_csv(tmp_path / "s.csv"), read_bvh(tmp_path / "s.bvh")
  idx = [bvh.skeleton.joint_names.index(n) for n in csv.skeleton.joint_names]
  assert np.abs(bvh.positions[:, idx] - csv.positions).max() < 1e-3 * height(csv)
  # on a character: the Mixamo rig's hierarchy, names and rest pose, driven by the generated motion
  mixamo = shared_data / "bvh" / "bvh_python" / "test_freebvh.bvh"
  assert cli.main([*args, "-o", str(tmp_path / "m.bvh"), "--skeleton", str(mixamo)]) == 0
  check_retargeted(tmp_path / "m.bvh", mixamo, csv)


# ---------------------------------------------------------------- mapping, dataset, CLI


def test_named_mappings_to_the_training_layout(shared_data):
  for path in [
    shared_data / "asfamc" / "cmu131" / "131_01.amc",
    shared_data / "bvh" / "cmu131" / "131_01.bvh",
    shared_data / "bvh" / "bandai" / "dataset-1_dance-short_normal_001.bvh",
  ]:
    m = to_mpii16(read_amc(path) if path.suffix == ".amc" else read_bvh(path))
    assert m.skeleton is MPII16 and m.positions.shape[1:] == (16, 3)
    y = m.positions[..., 1]  # y-up files: the head above the feet, the knees between
    assert y[:, 9].mean() > y[:, 6].mean() > y[:, 1].mean() > y[:, 0].mean()
    assert np.median(m.bone_lengths().std(0) / m.bone_lengths().mean(0)) < 0.05


def test_a_dataset_folder_may_mix_formats(shared_data, tmp_path):
  for src in [
    shared_data / "bvh" / "cmu131" / "131_01.bvh",
    shared_data / "asfamc" / "cmu131" / "131_02.amc",
    shared_data / "asfamc" / "cmu131" / "mjackson.asf",
    bundled_path("cmu94") / "94_01_skeleton_3d.csv",
  ]:
    (tmp_path / src.name).write_bytes(src.read_bytes())
  ds = load_dataset(tiny_config(f"data.dataset={str(tmp_path)!r}", "data.val_takes=[]").data)
  assert list(ds.id_map) == ["131_01", "131_02", "94_01_skeleton_3d"]
  assert all(x.shape[1] == 48 for _, x in ds.train)


def test_convert_info_and_render_on_every_format(shared_data, tmp_path, capsys):
  inputs = [
    shared_data / "bvh" / "cmu131" / "131_03.bvh",
    shared_data / "asfamc" / "cmu05" / "md_03.amc",
    shared_data / "bvh" / "bandai" / "dataset-1_walk_normal_002.bvh",
  ]
  out = tmp_path / "conv"
  assert cli.main(["data", "convert", *map(str, inputs), "-o", str(out), "--joints", "mpii16", "--like", "cmu94"]) == 0
  converted = sorted(out.glob("*.csv"))
  assert len(converted) == 3
  ref = np.mean([t.bone_lengths().mean() for t in map(read_csv, resolve_files("cmu94"))])
  for f in converted:
    m = read_csv(f)
    assert 0.8 * ref < m.bone_lengths().mean() < 1.2 * ref  # cmu94's body size, axes and rate
  assert cli.main(["data", "convert", str(inputs[0]), "-o", str(tmp_path / "x.bvh")]) == 0
  assert read_bvh(tmp_path / "x.bvh").num_frames == read_bvh(inputs[0]).num_frames
  assert cli.main(["data", "convert", str(inputs[0]), "-o", str(tmp_path / "x.bvh")]) == 2  # no silent overwrite
  c3d = shared_data / "c3d" / "cmu01" / "01_01.c3d"
  assert cli.main(["data", "info", *map(str, inputs), str(c3d)]) == 0
  table = capsys.readouterr().out
  for f in [*inputs, c3d]:  # one row per take: its name and frame count
    m = read_motions(f)[0]
    assert re.search(rf"{re.escape(m.name)}\W+{m.num_frames}\W", table), m.name
  assert cli.main(["render", *map(str, inputs), str(c3d), "-o", str(tmp_path / "all.html"), "--frames", "30"]) == 0
  assert cli.main(["render", str(c3d), "-o", str(tmp_path / "m.gif"), "--frames", "5"]) == 0


@pytest.mark.parametrize(
  "text, pattern",
  [
    (
      "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n"
      "  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\n"
      "  JOINT Spine\n  {\n    OFFSET 0 1 0\n",
      r"truncated HIERARCHY",
    ),
    (
      "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 4 Xposition Yposition Zposition Zrotation\n}\n"
      "MOTION\nFrames: 1\nFrame Time: 0.1\n0 0 0 0\n",
      r":5: channel-count mismatch",
    ),
    (
      "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 3 Zrotation Yrotation Xrotation\n}\n"
      "MOTION\nFrames: 2\nFrame Time: 0.1\n0 0 0\n0 0 0 0\n",
      r":11: 4 values, the hierarchy declares 3",
    ),
    (
      "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 3 Zrotation Yrotation Xrotation\n}\n"
      "MOTION\nFrames: 2\nFrame Time: 0.1\n0 0 0\n0 zero 0\n",
      r":11: not a number: 'zero'",
    ),
  ],
)
def test_malformed_bvh_errors_name_file_and_line(tmp_path, capsys, text, pattern):
  f = tmp_path / "bad.bvh"
  f.write_text(text)
  with pytest.raises(UserError, match=pattern) as e:
    read_bvh(f)
  assert str(e.value).startswith(str(f))
  assert cli.main(["data", "info", str(f)]) == 2
  assert capsys.readouterr().err.count("\n") == 1


def test_amc_bone_missing_from_the_asf(shared_data, tmp_path):
  src = shared_data / "asfamc" / "cmu131"
  (tmp_path / "mjackson.asf").write_bytes((src / "mjackson.asf").read_bytes())
  lines = (src / "131_01.amc").read_text().splitlines()[:40]
  lines[10] = "tail 1 2 3"
  (tmp_path / "x.amc").write_text("\n".join(lines))
  with pytest.raises(UserError, match=r"x\.amc:11: bone 'tail' is not in the skeleton mjackson\.asf"):
    read_amc(tmp_path / "x.amc")


def test_an_amc_finds_its_asf(shared_data, tmp_path):
  from chorjax.data.amc import find_asf

  asf = (shared_data / "asfamc" / "cmu131" / "mjackson.asf").read_bytes()
  only = tmp_path / "only"
  only.mkdir()
  (only / "whatever.asf").write_bytes(asf)
  assert find_asf(only / "131_01.amc") == only / "whatever.asf"  # the only .asf in the folder
  many = tmp_path / "many"
  many.mkdir()
  for name in ("01.asf", "0.asf", "charleston.asf", "charles.asf", "other.asf"):
    (many / name).write_bytes(asf)
  assert find_asf(many / "01_01.amc") == many / "01.asf"  # the longest prefix wins
  assert find_asf(many / "charleston1.amc") == many / "charleston.asf"
  with pytest.raises(UserError, match="pass --asf"):
    find_asf(many / "zzz.amc")


def test_units_to_metres_are_recorded(shared_data):
  from chorjax.data.amc import asf_metres_scale, read_asf

  src = shared_data / "asfamc" / "cmu131"
  scale = asf_metres_scale(read_asf(src / "mjackson.asf"))
  assert scale == pytest.approx(0.0564444, rel=1e-5)
  m = read_amc(src / "131_01.amc", scale=scale, units="m")
  assert m.units == "m"
  femur = np.linalg.norm(m.positions[:, 2] - m.positions[:, 1], axis=-1).mean()  # lfemur end - lhipjoint end
  assert 0.35 < femur < 0.5  # an adult thigh, in metres
  bandai = read_bvh(shared_data / "bvh" / "bandai" / "dataset-1_walk_normal_002.bvh", scale=0.01, units="m")
  assert bandai.units == "m" and 1.4 < np.ptp(bandai.positions[..., 1]) < 2.0  # a person's height


def test_scaled_copy_and_dropping_a_leading_frame(shared_data):
  src = shared_data / "bvh" / "cmu131"
  a = read_bvh(src / "131_01.bvh")
  metres = read_bvh(src / "scaled_131_01.bvh")  # the same take in metres, with one extra frame at the end
  assert metres.num_frames == a.num_frames + 1
  back = read_bvh(src / "scaled_131_01.bvh", scale=1 / 0.0564444)  # metres -> ASF units
  assert np.abs(back.positions[: a.num_frames] - a.positions).max() < 1e-3 * height(a)
  dropped = read_bvh(src / "131_01.bvh", drop_first_frame=True)  # a converter's leading T-pose frame
  assert dropped.num_frames == a.num_frames - 1
  np.testing.assert_array_equal(dropped.positions, a.positions[1:])


def test_unreadable_motion_files_are_one_line_errors(shared_data, tmp_path):
  (tmp_path / "d.bvh").mkdir()
  with pytest.raises(UserError, match=r"d\.bvh: cannot read as a BVH text file \(IsADirectoryError\)"):
    read_bvh(tmp_path / "d.bvh")
  with pytest.raises(UserError, match=r"missing\.amc: no such AMC file"):
    read_amc(tmp_path / "missing.amc", shared_data / "asfamc" / "cmu131" / "mjackson.asf")


@pytest.mark.parametrize("ext", ["csv", "npz", "bvh"])
def test_every_format_chorjax_writes_reads_back_onto_the_16_joints(tmp_path, ext):
  """What chorjax writes, chorjax reads back with `--joints mpii16`: its own joint names are a known rig (a
  BVH of the 16 joints was once refused as a skeleton it could not place), the bundled takes within 1e-3 of
  the body's height."""
  for path in resolve_files("cmu94")[::9]:
    take = read_csv(path)
    out = tmp_path / f"{path.stem}.{ext}"
    assert cli.main(["data", "convert", str(path), "-o", str(out)]) == 0
    back_dir = tmp_path / f"back_{ext}"
    assert cli.main(["data", "convert", str(out), "--joints", "mpii16", "-o", str(back_dir)]) == 0
    back = read_csv(back_dir / f"{path.stem}.csv")
    assert back.skeleton.joint_names == MPII16.joint_names
    assert np.abs(back.positions - take.positions).max() < 1e-3 * height(take), ext


def test_a_bvh_of_joint_names_with_spaces_braces_or_markup_reads_back(tmp_path):
  """BVH names are single tokens: a take whose joint names hold spaces ('right foot') or braces wrote a file
  chorjax could not read back ("expected '{' after right"). They are written as unique tokens."""
  import dataclasses

  from chorjax.data.bvh import bvh_names

  take = read_csv(resolve_files("cmu94")[0])
  names = list(take.skeleton.joint_names)
  names[:4] = ["right foot", "<b>knee</b>", "right_foot", "left {hip}"]
  odd = take.replace(skeleton=dataclasses.replace(take.skeleton, joint_names=tuple(names)))
  back = read_bvh(write_bvh(odd, tmp_path / "odd.bvh"))
  written = bvh_names(names)
  assert written[:4] == ["right_foot", "<b>knee</b>", "right_foot_2", "left_hip_"]
  idx = [back.skeleton.joint_names.index(n) for n in written]
  assert np.abs(back.positions[:, idx] - take.positions).max() < 1e-3 * height(take)


def test_readers_work_under_an_address_space_limit_of_4_gb(shared_data):
  """Clusters cap a job's address space: the C3D reader's child once raised its own limit above the inherited
  one and failed on every file; under 4 GB a C3D, a BVH and an AMC read as without the limit."""
  import subprocess
  import sys

  # the limit set in the child before chorjax loads (a preexec_fn would fork this multithreaded process)
  capped = (
    "import resource, runpy, sys; resource.setrlimit(resource.RLIMIT_AS, (4 * 10**9, 4 * 10**9)); "
    "sys.argv = ['chorjax', *sys.argv[1:]]; runpy.run_module('chorjax.cli', run_name='__main__')"
  )
  for path in (
    shared_data / "c3d" / "ezc3d" / "Qualisys.c3d",
    shared_data / "bvh" / "cmu131" / "131_01.bvh",
    shared_data / "asfamc" / "cmu131" / "131_01.amc",
  ):
    done = subprocess.run([sys.executable, "-c", capped, "data", "info", str(path)], capture_output=True, text=True)
    assert done.returncode == 0, (path.name, done.stderr[-500:])
    assert path.stem in done.stdout
