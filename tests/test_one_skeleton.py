"""One take, one skeleton: the same take read from two formats, converters' rest frames, empty files.

Everything here reads the real recordings in ../shared/data.
"""

import struct

import numpy as np
import pytest

from chorjax import cli
from chorjax.data import amc as amc_reader
from chorjax.data.bvh import read_bvh
from chorjax.data.check import check_paths, drop_leading_rest, find_jumps
from chorjax.data.dataset import conform, read_takes, resolve_files, to_rate, to_up_axis
from chorjax.data.mapping import HEAD_TOP_FROM_EYES, TARGETS, find_mapping, to_mpii16
from chorjax.data.skeletons import MPII16
from chorjax.sections import DataConfig

UPPER = [
  TARGETS.index(n)
  for n in TARGETS
  if n not in {"pelvis", *(f"{s}_{p}" for s in ("left", "right") for p in ("hip", "knee", "foot"))}
]


def _body(p) -> float:
  return float(np.ptp(p.reshape(-1, 3), axis=0).max())


@pytest.mark.parametrize("take", ["131_01", "131_02", "131_03"])
def test_amc_and_bvh_of_one_take_differ_only_by_the_thorax_bone_the_bvh_lacks(shared_data, take, monkeypatch):
  amc_path = shared_data / "asfamc" / "cmu131" / f"{take}.amc"
  bvh = to_mpii16(read_bvh(shared_data / "bvh" / "cmu131" / f"{take}.bvh")).positions
  amc = to_mpii16(amc_reader.read_amc(amc_path)).positions
  assert amc.shape == bvh.shape
  size = _body(amc)
  gap = np.linalg.norm(amc - bvh, axis=-1)  # [T, 16]
  lower = [j for j in range(16) if j not in UPPER]
  assert gap[:, lower].max() < 1e-5 * size  # legs and pelvis: the same joints
  # the upper body is one bone off in every frame: exactly the ASF's thorax bone (1.98337 units), which
  # the BVH release does not have (its lowerneck and collars sit at Chest2 with offset 0)
  np.testing.assert_allclose(gap[:, UPPER], 1.98337, atol=1e-3)
  read_asf = amc_reader.read_asf

  def without_thorax(path):
    asf = read_asf(path)
    asf.bones["thorax"]["length"] = 0.0
    return asf

  monkeypatch.setattr(amc_reader, "read_asf", without_thorax)
  same = to_mpii16(amc_reader.read_amc(amc_path)).positions
  assert np.abs(same - bvh).max() < 1e-5 * size  # both readers are exact: the files differ, not we


def test_data_check_names_a_take_whose_body_differs_from_the_others(shared_data):
  reports, _ = check_paths([str(shared_data / "asfamc" / "cmu131" / "131_01.amc"), str(shared_data / "bvh" / "cmu131")])
  notes = {r.path.split("/")[-1] + ("" if "asfamc" not in r.path else "(amc)"): r.notes for r in reports}
  assert any("pelvis-thorax bone is 1.4" in n for n in notes["131_01.amc(amc)"])
  assert any("0.0564x the size" in n for n in notes["scaled_131_01.bvh"])
  assert not any("another body" in n or "size of the other" in n for n in notes["131_02.bvh"] + notes["131_03.bvh"])


def test_every_aclstm_take_loses_its_leading_rest_pose(shared_data):
  files = [f for d in ("salsa", "martial", "indian") for f in resolve_files(str(shared_data / "aclstm" / d))]
  assert len(files) == 31
  for f in files:
    motion = read_bvh(f)
    jumps = find_jumps(motion)
    assert jumps.leading >= 1 and jumps.lead_ratio > 4, f
    kept, dropped = drop_leading_rest(motion)
    assert dropped == jumps.leading and kept.num_frames == motion.num_frames - dropped
    p = kept.positions.astype(np.float64)
    pose = p - p[:, kept.skeleton.root : kept.skeleton.root + 1]
    step = np.linalg.norm(np.diff(pose, axis=0), axis=-1).max(-1)
    assert step[0] <= 3 * np.percentile(step, 99), f  # no frame-0 jump left
    assert find_jumps(kept).leading == 0, f


def test_data_check_lists_rest_frames_and_jumps_with_frame_numbers(shared_data):
  reports, _ = check_paths([str(shared_data / "aclstm" / "salsa" / "15.bvh"), str(shared_data / "aclstm" / "martial")])
  for r in reports:
    assert any(n.startswith("frame 0 is a rest pose") for n in r.notes), r.path
  salsa = next(r for r in reports if r.path.endswith("15.bvh"))
  assert any("jumps away and back at frame(s) 733, 734, 735" in n for n in salsa.notes)
  assert any("the root jumps at frame(s) 734" in n for n in salsa.notes) and salsa.teleports == 1


def test_no_other_shared_take_has_a_rest_frame_or_a_jump(shared_data):
  specs = ["cmu94", *(str(shared_data / d) for d in ("asfamc/cmu05", "asfamc/cmu131", "bvh/bandai", "bvh/pymo"))]
  specs += [
    str(shared_data / "bvh" / "cmu131"),
    str(shared_data / "bvh" / "bvh_python"),
    str(shared_data / "c3d" / "cmu01"),
  ]
  seen = 0
  for spec in specs:
    for m in read_takes([spec]):
      j = find_jumps(m)
      assert (j.leading, j.pose, j.root) == (0, (), ()), (m.source, j)
      seen += 1
  assert seen == 10 + 5 + 4 + 3 + 1 + 4 + 2 + 1


def test_convert_drops_a_leading_rest_pose_by_default_and_keeps_it_on_request(shared_data, tmp_path, capsys):
  take = shared_data / "aclstm" / "martial" / "04.bvh"
  frames = read_bvh(take).num_frames
  assert cli.main(["data", "convert", str(take), "-o", str(tmp_path / "a"), "--joints", "mpii16"]) == 0
  out = capsys.readouterr().out
  assert "dropped a leading rest pose (4 frames) of 04; --keep-rest-frames keeps it" in out
  assert f"({frames - 4} frames, 16 joints" in out
  assert (
    cli.main(["data", "convert", str(take), "-o", str(tmp_path / "b"), "--joints", "mpii16", "--keep-rest-frames"]) == 0
  )
  out = capsys.readouterr().out
  assert "dropped" not in out and f"({frames} frames, 16 joints" in out


def test_training_drops_a_leading_rest_pose_with_a_note_unless_told(shared_data):
  spec = str(shared_data / "aclstm" / "martial" / "04.bvh")
  raw = read_takes([spec])
  for keep, want in ((False, raw[0].num_frames - 4), (True, raw[0].num_frames)):
    cfg = DataConfig(dataset=spec, up_axis="y", keep_rest_frames=keep)
    notes: list = []
    (m,) = conform(raw, cfg, {}, notes)
    assert m.num_frames == want
    assert notes == (
      [] if keep else ["dropped a leading rest pose (4 frames) of 04; data.keep_rest_frames = true keeps it"]
    )


def test_a_file_of_zero_frames_is_one_line_exit_2_in_every_format(shared_data, tmp_path, capsys):
  bvh = (shared_data / "bvh" / "cmu131" / "131_01.bvh").read_text()
  (tmp_path / "empty.bvh").write_text(bvh[: bvh.index("MOTION")] + "MOTION\nFrames: 0\nFrame Time: 0.0083333\n")
  (tmp_path / "empty.csv").write_text("")
  (tmp_path / "mjackson.asf").write_bytes((shared_data / "asfamc" / "cmu131" / "mjackson.asf").read_bytes())
  (tmp_path / "empty.amc").write_text(":FULLY-SPECIFIED\n:DEGREES\n")
  from chorjax.data.npz import write_npz

  write_npz(
    tmp_path / "empty.npz", np.zeros((1, 0, 16, 3)), fps=30.0, skeleton=MPII16, up_axis="-y", units="x", settings={}
  )
  c3d = bytearray((shared_data / "c3d" / "ezc3d" / "Qualisys.c3d").read_bytes())
  first = struct.unpack("<H", c3d[6:8])[0]
  c3d[8:10] = struct.pack("<H", first - 1)  # the header's last frame before its first: no frames
  (tmp_path / "empty.c3d").write_bytes(bytes(c3d))
  for name in ("empty.bvh", "empty.csv", "empty.amc", "empty.npz", "empty.c3d"):
    assert cli.main(["data", "info", str(tmp_path / name)]) == 2, name
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(tmp_path / name) in err[0] and "Traceback" not in err[0], err
  assert "'Frames: 0': the MOTION section holds no frame" in cli_error(tmp_path / "empty.bvh", capsys)


def cli_error(path, capsys) -> str:
  cli.main(["data", "info", str(path)])
  return capsys.readouterr().err


def test_a_head_without_an_end_site_gets_its_top_from_the_eyes(shared_data):
  take = read_bvh(shared_data / "aclstm" / "indian" / "04.bvh")
  mapping = find_mapping(take)
  assert mapping.joints["head_top"] == HEAD_TOP_FROM_EYES and mapping.joints["neck"] == "head"
  p = to_mpii16(drop_leading_rest(take)[0]).positions
  j = TARGETS.index
  neck_top = np.linalg.norm(p[:, j("head_top")] - p[:, j("neck")], axis=-1)
  assert neck_top.std() / neck_top.mean() < 1e-3  # it turns with the head: a rigid bone
  # its share of the body is the CMU ASF head bone's (where the layout's head top is, about eye level)
  share = lambda q: (
    np.linalg.norm(q[:, j("head_top")] - q[:, j("neck")], axis=-1).mean()
    / sum(np.linalg.norm(q[:, c] - q[:, a], axis=-1).mean() for a, c in MPII16.bones)
  )
  asf = to_mpii16(amc_reader.read_amc(shared_data / "asfamc" / "cmu131" / "131_01.amc")).positions
  assert 0.9 < share(p) / share(asf) < 1.1  # 0.0240 vs 0.0249; the head joint alone gave 0.0184
  bandai = read_bvh(shared_data / "bvh" / "bandai" / "dataset-1_dance-short_normal_001.bvh")
  assert HEAD_TOP_FROM_EYES not in find_mapping(bandai).joints.values()  # no eyes: unchanged


def test_the_94_04_csv_and_the_aclstm_bvh_are_one_take_mirrored(shared_data):
  """The bundled CSV of 94_04 and acLSTM's 120 fps BVH of it are mirror images (left and right swapped
  in a mirrored world: each is right-handed with its own labels), on two skeletons; resampled to 30 fps,
  aligned in time and by one rotation, they hold the same pose."""
  csv = read_takes(["cmu94/94_04_skeleton_3d.csv"])[0]
  bvh = drop_leading_rest(read_bvh(shared_data / "aclstm" / "indian" / "04.bvh"))[0]
  bvh = to_rate(to_up_axis(to_mpii16(bvh), csv.up_axis), csv.fps)
  parent, child = np.array(MPII16.bones).T

  def directions(p):
    v = p[:, child] - p[:, parent]
    return v / np.linalg.norm(v, axis=-1, keepdims=True)

  want = directions(csv.positions.astype(np.float64))

  def best_angle(p):  # degrees: mean bone angle of the best time offset and rotation
    have, out = directions(p), []
    for off in range(bvh.num_frames - csv.num_frames + 1):
      h = have[off : off + csv.num_frames]
      u, _, vt = np.linalg.svd(h.reshape(-1, 3).T @ want.reshape(-1, 3))
      cos = (want * (h @ (vt.T @ u.T).T)).sum(-1)
      out.append(np.degrees(np.arccos(np.clip(cos, -1, 1))).mean(1))
    return min(out, key=np.median)

  mirrored = best_angle(bvh.positions.astype(np.float64)[:, list(MPII16.twins)])
  assert np.median(mirrored) < 20 and np.percentile(mirrored, 95) < 25  # measured: 16.0 / 20.6 degrees
  assert np.median(best_angle(bvh.positions.astype(np.float64))) > 30  # as labelled: another pose
  # bone proportions (each bone's share of the body / the CSV's): the sources' skeletons differ (the rig's
  # thigh 0.78x, its pelvis-thorax 1.62x; CMU's own ASF differs from the CSV layout by 0.5-1.9x) ...
  share = lambda q: (lambda b: b / b.sum())(np.linalg.norm(q[:, child] - q[:, parent], axis=-1).mean(0))
  ratio = share(bvh.positions) / share(csv.positions)
  top = MPII16.bones.index((TARGETS.index("neck"), TARGETS.index("head_top")))
  assert np.delete(ratio, top).min() > 0.75 and np.delete(ratio, top).max() < 1.65, np.round(ratio, 2)
  # ... and the head top is ours: put where CMU's ASF head bone ends, whose share is 0.72x the CSV's
  asf = to_mpii16(amc_reader.read_amc(shared_data / "asfamc" / "cmu131" / "131_01.amc")).positions
  assert abs(ratio[top] / (share(asf) / share(csv.positions))[top] - 1) < 0.1  # 0.70 vs 0.72
