"""Automatic skeleton mapping onto the 16-joint layout: names, topology, mapping files, real rigs."""

import re

import numpy as np
import pytest

from chorjax.data.amc import read_amc
from chorjax.data.bvh import read_bvh
from chorjax.data.joint_names import split_name
from chorjax.data.mapping import find_mapping, map_takes, read_joint_map, to_mpii16
from chorjax.data.skeletons import MPII16
from chorjax.errors import UserError

# The joints of the CMU 131 BVH takes (as bvh11 names them) under the namings of other tools.
CONVERTER = {  # a CMU take exported by the common MotionBuilder-friendly converter
  "LeftHip": "LeftUpLeg",
  "LeftKnee": "LeftLeg",
  "LeftAnkle": "LeftFoot",
  "LeftToe": "LeftToeBase",
  "lowerback": "LowerBack",
  "Chest": "Spine",
  "Chest2": "Spine1",
  "lowerneck": "Neck",
  "Neck": "Neck1",
  "LeftCollar": "LeftShoulder",
  "LeftShoulder": "LeftArm",
  "LeftElbow": "LeftForeArm",
  "LeftWrist": "LeftHand",
  "lhand": "LeftFingerBase",
  "LFingers": "LeftHandIndex1",
}
SMPL = {
  "Hips": "pelvis",
  "LHipJoint": "left_hip_offset",
  "LeftHip": "left_hip",
  "LeftKnee": "left_knee",
  "LeftAnkle": "left_ankle",
  "LeftToe": "left_foot",
  "lowerback": "spine1",
  "Chest": "spine2",
  "Chest2": "spine3",
  "lowerneck": "neck",
  "Neck": "neck_upper",
  "Head": "head",
  "LeftCollar": "left_collar",
  "LeftShoulder": "left_shoulder",
  "LeftElbow": "left_elbow",
  "LeftWrist": "left_wrist",
  "lhand": "left_hand",
  "LFingers": "left_fingers",
  "LThumb": "left_thumb",
}
KINECT = {
  "Hips": "SpineBase",
  "LHipJoint": "HipRootLeft",
  "LeftHip": "HipLeft",
  "LeftKnee": "KneeLeft",
  "LeftAnkle": "AnkleLeft",
  "LeftToe": "FootLeft",
  "lowerback": "SpineMid",
  "Chest": "SpineUpper",
  "Chest2": "SpineShoulder",
  "lowerneck": "Neck",
  "Neck": "NeckUpper",
  "LeftCollar": "ClavicleLeft",
  "LeftShoulder": "ShoulderLeft",
  "LeftElbow": "ElbowLeft",
  "LeftWrist": "WristLeft",
  "lhand": "HandLeft",
  "LFingers": "HandTipLeft",
  "LThumb": "ThumbLeft",
}
BLENDER = {  # Rigify-style deform bones, side as a .L/.R suffix
  "Hips": "hips",
  "LHipJoint": "pelvis.L",
  "LeftHip": "thigh.L",
  "LeftKnee": "shin.L",
  "LeftAnkle": "foot.L",
  "LeftToe": "toe.L",
  "lowerback": "spine",
  "Chest": "spine.001",
  "Chest2": "chest",
  "lowerneck": "neck",
  "Neck": "neck.001",
  "Head": "head",
  "LeftCollar": "shoulder.L",
  "LeftShoulder": "upper_arm.L",
  "LeftElbow": "forearm.L",
  "LeftWrist": "hand.L",
  "lhand": "palm.L",
  "LFingers": "f_index.L",
  "LThumb": "thumb.L",
}


def _mirror(table):
  """The right side of a naming from its left side."""
  out = dict(table)
  for src, dst in table.items():
    for a, b in (
      ("Left", "Right"),
      ("left", "right"),
      ("LHip", "RHip"),
      ("lhand", "rhand"),
      ("LF", "RF"),
      ("LT", "RT"),
    ):
      if src.startswith(a):
        d = dst
        for x, y in (("Left", "Right"), ("left", "right"), (".L", ".R")):
          d = d.replace(x, y)
        out[b + src[len(a) :]] = d
  return out


def _renamed_bvh(src, dst, table, prefix="", mirror=True):
  """``src`` with every ROOT/JOINT renamed by ``table`` (others keep their name) and ``prefix`` added;
  ``mirror``: ``table`` names the left side only, the right follows."""
  table = _mirror(table) if mirror else table
  text = src.read_text()

  def rename(m):
    return f"{m.group(1)} {prefix}{table.get(m.group(2), m.group(2))}"

  dst.write_text(re.sub(r"(ROOT|JOINT)\s+(\S+)", rename, text))
  return dst


@pytest.fixture(scope="module")
def cmu131(shared_data):
  path = shared_data / "bvh" / "cmu131" / "131_01.bvh"
  return path, to_mpii16(read_bvh(path)).positions


@pytest.mark.parametrize(
  "table, prefix",
  [(CONVERTER, ""), (CONVERTER, "mixamorig:"), (SMPL, ""), (KINECT, ""), (BLENDER, "")],
  ids=["converter", "mixamo", "smpl", "kinect", "blender"],
)
def test_one_take_under_other_namings_maps_to_the_same_joints(cmu131, tmp_path, table, prefix):
  path, want = cmu131
  renamed = read_bvh(_renamed_bvh(path, tmp_path / "take.bvh", table, prefix))
  assert renamed.skeleton.joint_names != read_bvh(path).skeleton.joint_names
  mapping = find_mapping(renamed)
  assert mapping.method == "names"
  np.testing.assert_array_equal(to_mpii16(renamed).positions, want)


def test_names_that_say_nothing_map_by_topology(cmu131, tmp_path):
  path, want = cmu131
  names = read_bvh(path).skeleton.joint_names
  anonymous = read_bvh(
    _renamed_bvh(path, tmp_path / "take.bvh", {n: f"j{k}" for k, n in enumerate(names)}, mirror=False)
  )
  assert find_mapping(anonymous).method == "topology"
  np.testing.assert_array_equal(to_mpii16(anonymous).positions, want)


def _every_file(shared_data):
  return sorted((shared_data / "bvh").glob("*/*.bvh")) + sorted((shared_data / "asfamc").glob("*/*.amc"))


def test_every_bvh_and_asf_in_shared_data_maps_automatically(shared_data):
  methods = {}
  for path in _every_file(shared_data):
    motion = read_amc(path) if path.suffix == ".amc" else read_bvh(path)
    mapping = find_mapping(motion)
    methods[path.name] = mapping.method
    m = to_mpii16(motion)
    assert m.skeleton is MPII16
    y = m.positions[..., 1]  # y-up files: the head above the neck above the pelvis above the knees
    j = {n: i for i, n in enumerate(MPII16.joint_names)}
    assert y[:, j["head_top"]].mean() > y[:, j["neck"]].mean() > y[:, j["pelvis"]].mean()
    assert y[:, j["pelvis"]].mean() > y[:, j["left_knee"]].mean() > y[:, j["left_foot"]].mean()
    # left is left: on the character's left of its facing direction (the toes' way; right-handed axes)
    lr = (m.positions[:, j["left_hip"]] - m.positions[:, j["right_hip"]]).mean(0)
    chest_lr = (m.positions[:, j["left_shoulder"]] - m.positions[:, j["right_shoulder"]]).mean(0)
    assert lr @ chest_lr > 0
    if motion.skeleton.bones and path.suffix == ".bvh":  # the same joints with the names taken away
      anon = motion.replace(skeleton=_anonymous(motion.skeleton))
      assert find_mapping(anon).method == "topology", path.name
      np.testing.assert_array_equal(to_mpii16(anon).positions, m.positions, err_msg=path.name)
  assert methods["test_freebvh.bvh"] == methods["test_mocapbank.bvh"] == "names"  # the mixamo and mocapbank rigs
  assert {methods[p.name] for p in _every_file(shared_data) if p.suffix == ".amc"} == {"cmu_asf"}


def _anonymous(sk):
  import dataclasses

  return dataclasses.replace(sk, joint_names=tuple(f"j{k}" for k in range(sk.num_joints)))


def test_left_and_right_by_topology_follow_the_body(shared_data):
  motion = read_bvh(shared_data / "bvh" / "bvh_python" / "test_freebvh.bvh")
  mirrored = motion.replace(positions=motion.positions * np.array([-1, 1, 1], np.float32))
  anon = mirrored.replace(skeleton=_anonymous(motion.skeleton))
  # mirrored, the rig's "Right" chains are on the body's left: topology follows the body, not the order
  got = find_mapping(anon).joints
  names = motion.skeleton.joint_names
  for side, other in (("left", "Right"), ("right", "Left")):
    assert names[int(got[f"{side}_hand"][1:])] == f"mixamorig:{other}Hand"
    assert names[int(got[f"{side}_foot"][1:])] == f"mixamorig:{other}Foot"


@pytest.mark.parametrize(
  "name, want",
  [
    ("mixamorig:LeftUpLeg", ("left", "upleg", False)),
    ("LeftForeArm", ("left", "forearm", False)),
    ("Foot_R", ("right", "foot", False)),
    ("UpperArm_L", ("left", "upperarm", False)),
    ("ShoulderLeft", ("left", "shoulder", False)),
    ("left_ankle", ("left", "ankle", False)),
    ("L_Knee", ("left", "knee", False)),
    ("thigh.R", ("right", "thigh", False)),
    ("lhand", ("left", "hand", False)),
    ("LHipJoint", ("left", "hipjoint", False)),
    ("Head_end", (None, "head", True)),
    ("mixamorig:HeadTop_End", (None, "headtop", True)),
    ("Hips", (None, "hips", False)),
    ("Bip01 L Thigh", ("left", "thigh", False)),
    ("LowerLeg_L", ("left", "lowerleg", False)),
  ],
)
def test_joint_names_are_normalized(name, want):
  assert split_name(name) == want


def test_a_joint_map_file_places_any_skeleton(shared_data, tmp_path):
  motion = read_bvh(shared_data / "bvh" / "bvh_python" / "test_mocapbank.bvh")
  auto = find_mapping(motion)
  good = tmp_path / "map.toml"
  good.write_text("".join(f'{t} = "{s}"\n' for t, s in auto.joints.items()))
  mapped = find_mapping(motion, good)
  assert mapped.method == f"file:{good}" and mapped.joints == auto.joints
  partial = tmp_path / "partial.toml"
  partial.write_text('pelvis = "Hips"\nleft_knee = "LeftKnee"\n')
  with pytest.raises(UserError, match=r"partial.toml: not placed: right_foot, right_knee.*has: Hips, Chest"):
    find_mapping(motion, partial)
  wrong = tmp_path / "wrong.toml"
  wrong.write_text(good.read_text().replace('"LeftKnee"', '"LeftKneee"'))
  with pytest.raises(UserError, match=r"no such joint in the file: left_knee=LeftKneee"):
    find_mapping(motion, wrong)
  crossed = tmp_path / "crossed.toml"
  crossed.write_text(good.read_text().replace('left_knee = "LeftKnee"', 'left_knee = "RightKnee"'))
  with pytest.raises(UserError, match=r"crossed.toml: .*(same joint|not above)"):
    find_mapping(motion, crossed)
  unknown = tmp_path / "unknown.toml"
  unknown.write_text('left_toe = "LeftAnkle_end"\n')
  with pytest.raises(UserError, match=r"unknown target joint 'left_toe'"):
    find_mapping(motion, unknown)


def test_one_mapping_per_skeleton_in_a_dataset(shared_data):
  # the Bandai dance's head End Site has no length, the walk's has: one reading for the whole set
  takes = [read_bvh(p) for p in sorted((shared_data / "bvh" / "bandai").glob("*.bvh"))]
  alone = {t.name: find_mapping(t).joints["head_top"] for t in takes}
  assert len(set(alone.values())) == 2
  _, used = map_takes(takes)
  assert len({m.joints["head_top"] for m in used.values()}) == 1


def test_a_skeleton_that_cannot_be_placed_lists_its_joints(shared_data):
  motion = read_bvh(shared_data / "bvh" / "bvh_python" / "test_mocapbank.bvh")
  from chorjax.data.motion import Skeleton

  names = tuple(f"j{k}" for k in range(motion.skeleton.num_joints))
  flat = Skeleton("flat", names, (-1,) + (0,) * (len(names) - 1), tuple(range(len(names))))
  with pytest.raises(UserError, match=r"could not place the 16 training joints.*j0, j1, j2.*joint_map"):
    to_mpii16(motion.replace(skeleton=flat))


def test_a_folder_of_mixamo_bvh_trains_with_only_the_dataset_set(shared_data, tmp_path, capsys):
  from helpers import TINY

  from chorjax import cli
  from chorjax.run import load_run

  folder = tmp_path / "mixamo"
  folder.mkdir()
  for take in ("131_01", "131_02"):
    _renamed_bvh(shared_data / "bvh" / "cmu131" / f"{take}.bvh", folder / f"{take}.bvh", CONVERTER, "mixamorig:")
  (tmp_path / "defaults.toml").write_text("")  # nothing but the dataset
  code = cli.main(
    ["train", str(tmp_path / "defaults.toml"), *TINY, f"data.dataset={folder}", "--workdir", str(tmp_path / "run")]
  )
  out = capsys.readouterr().out
  assert code == 0
  assert "joints of 131_01 and 1 more mapped by names: right_foot=mixamorig:RightFoot" in out
  run = load_run(tmp_path / "run")
  assert run.joint_maps["131_02"]["method"] == "names"
  assert run.joint_maps["131_02"]["joints"]["left_shoulder"] == "mixamorig:LeftArm"


@pytest.mark.parametrize(
  "content, message",
  [
    (None, "no such joint-map file"),
    (b"[joints\nhead = 'x'\n", "invalid TOML: Expected ']'"),
    (b"\xff\xfe head", "cannot read as a joint-map text file"),
    (b"right_foot = 3\n", "right_foot must name one source joint"),
    (b'tail = "x"\n', "unknown target joint 'tail'"),
  ],
)
def test_a_bad_joint_map_file_is_one_line_naming_it(tmp_path, content, message):
  path = tmp_path / "map.toml"
  if content is not None:
    path.write_bytes(content)
  with pytest.raises(UserError, match=rf"^{re.escape(str(path))}: .*{re.escape(message)}") as e:
    read_joint_map(path)
  assert "\n" not in str(e.value)
