"""Retargeted BVH out: the 16-joint motion on a character's own hierarchy, read back two ways."""

import numpy as np
import pytest

from chorjax import cli
from chorjax.data.bvh import _parse_motion, read_bvh
from chorjax.data.csv import read_csv
from chorjax.data.dataset import bundled_path, to_up_axis
from chorjax.data.mapping import find_mapping, to_mpii16
from chorjax.data.skeletons import MPII16
from chorjax.errors import UserError

TAKE = bundled_path("cmu94") / "94_01_skeleton_3d.csv"


def _cosines(a, b):
  """Per bone of the 16-joint layout: the smallest cosine over frames between a's and b's directions."""
  out = {}
  for p, c in MPII16.bones:
    u, v = a[:, c] - a[:, p], b[:, c] - b[:, p]
    cos = np.sum(u * v, -1) / np.linalg.norm(u, axis=-1) / np.linalg.norm(v, axis=-1)
    out[MPII16.joint_names[c]] = float(cos.min())
  return out


def _facing(p):
  """Heading angle per frame: the hips' left-right line turned a quarter about y (y up)."""
  j = MPII16.joint_names.index
  lr = p[:, j("left_hip")] - p[:, j("right_hip")]
  return np.arctan2(lr[:, 0], -lr[:, 2])


def check_retargeted(path, character, want):
  """``path`` (a retargeted BVH) plays ``want`` (16 joints, any up axis) on ``character``."""
  from bvh import Bvh

  back, char = read_bvh(path), read_bvh(character)
  assert back.skeleton.joint_names == char.skeleton.joint_names  # its hierarchy, names and order
  text = path.read_text()
  assert text[: text.index("MOTION")].strip() == character.read_text()[: character.read_text().index("MOTION")].strip()
  # an independent reader sees the same joints, frames and channel values
  other = Bvh(text)
  assert other.nframes == back.num_frames == want.num_frames
  names = list(other.get_joints_names())
  assert names == [n for n in char.skeleton.joint_names if n in names]
  rows, _ = _parse_motion(path, text, sum(len(other.joint_channels(n)) for n in names))
  col = 0
  for n in names:
    k = len(other.joint_channels(n))
    got = np.array([other.frame_joint_channels(f, n, other.joint_channels(n)) for f in (0, want.num_frames - 1)])
    np.testing.assert_allclose(got, rows[[0, -1], col : col + k], atol=1e-6)
    col += k
  # mapped back onto the 16 joints: the generated motion on the character's proportions
  mapped = to_mpii16(back).positions
  gen = np.asarray(to_up_axis(want, "y").positions)
  cos = _cosines(mapped, gen)
  limbs = [f"{s}_{p}" for s in ("left", "right") for p in ("knee", "foot", "elbow", "hand")] + ["head_top"]
  assert min(cos[n] for n in limbs) > 0.999, cos  # one child: the direction exactly
  assert cos["thorax"] > 0.98, cos  # the spine: turned at its first joint along pelvis -> thorax
  turn = np.angle(np.exp(1j * (_facing(mapped) - _facing(gen))))
  off = np.abs(turn - np.median(turn))  # facing follows the dance (the rest pose's offset aside)
  assert np.percentile(off, 99) < np.deg2rad(2) and off.max() < np.deg2rad(10)  # best fits of unlike triangles
  return back, mapped


def test_convert_retargets_a_take_onto_the_mixamo_rig(shared_data, tmp_path):
  character = shared_data / "bvh" / "bvh_python" / "test_freebvh.bvh"
  out = tmp_path / "on_mixamo.bvh"
  assert cli.main(["data", "convert", str(TAKE), "-o", str(out), "--skeleton", str(character)]) == 0
  want = read_csv(TAKE)
  back, mapped = check_retargeted(out, character, want)
  assert find_mapping(back).method == "names"
  j = MPII16.joint_names.index
  # root translation on the character's scale: the pelvis path is the take's, times leg length ratio
  gen = np.asarray(to_up_axis(want, "y").positions)
  steps = np.linalg.norm(np.diff(mapped[:, j("pelvis"), [0, 2]], axis=0), axis=-1).sum()
  want_steps = np.linalg.norm(np.diff(gen[:, j("pelvis"), [0, 2]], axis=0), axis=-1).sum()
  legs = lambda p: (
    np.linalg.norm(p[:, j("left_hip")] - p[:, j("left_knee")], axis=-1).mean()
    + np.linalg.norm(p[:, j("left_knee")] - p[:, j("left_foot")], axis=-1).mean()
  )
  assert steps / want_steps == pytest.approx(legs(mapped) / legs(gen), rel=0.05)
  # the fingers, eyes and toes stay at rest relative to their parents
  char = read_bvh(character)
  k, parent = char.skeleton.joint_names.index("mixamorig:LeftHandIndex2"), "mixamorig:LeftHandIndex1"
  p = char.skeleton.joint_names.index(parent)
  bone = lambda m: np.linalg.norm(m.positions[:, k] - m.positions[:, p], axis=-1)
  np.testing.assert_allclose(bone(back), bone(char).mean(), rtol=1e-4)


def test_retargeting_onto_a_rig_with_a_root_below_the_hips(shared_data, tmp_path):
  character = shared_data / "bvh" / "bandai" / "dataset-1_dance-short_normal_001.bvh"  # joint_Root on the floor
  out = tmp_path / "on_bandai.bvh"
  assert cli.main(["data", "convert", str(TAKE), "-o", str(out), "--skeleton", str(character)]) == 0
  _, mapped = check_retargeted(out, character, read_csv(TAKE))
  j = MPII16.joint_names.index
  feet = np.minimum(mapped[:, j("left_foot"), 1], mapped[:, j("right_foot"), 1])
  char = to_mpii16(read_bvh(character)).positions
  rest_ankle = np.percentile(np.minimum(char[:, j("left_foot"), 1], char[:, j("right_foot"), 1]), 5)
  assert abs(np.percentile(feet, 5) - rest_ankle) < 0.1 * np.ptp(char[..., 1])  # its feet on its floor


def test_skeleton_needs_a_bvh_output_and_a_readable_character(shared_data, tmp_path, capsys):
  character = shared_data / "bvh" / "bvh_python" / "test_freebvh.bvh"
  assert cli.main(["data", "convert", str(TAKE), "-o", str(tmp_path / "x"), "--skeleton", str(character)]) == 2
  assert "retargeting writes BVH; give -o OUT.bvh" in capsys.readouterr().err
  bad = tmp_path / "bad.bvh"
  bad.write_text("HIERARCHY\nROOT Hips\n{\n")
  with pytest.raises(UserError, match=r"bad\.bvh"):
    from chorjax.data.retarget import Character

    Character(bad)
  assert not (tmp_path / "x").exists()
