"""Property-based tests of every reader over mutations of the real files in ../shared/data (issue 40).

Each reader gets a real file cut down to a few frames, then a list of mutations drawn by hypothesis:
truncation, dropped, duplicated and swapped lines, swapped tokens, numbers replaced by non-finite, huge or
malformed ones, bytes flipped (binary formats). Whatever comes out must be a motion with finite values or a
one-line ``UserError`` that names the file, nothing else (no other exception, no hang).

Profiles (``CHORJAX_FUZZ``): ``ci`` (default: 40 examples per reader, a fixed seed, well under a minute) and
``long`` (10,000 examples per reader, random seeds), the local run reported in issue 40:

    CHORJAX_FUZZ=long pytest tests/test_fuzz.py -n0 -q
"""

import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from helpers import read_or_refused
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from chorjax.data.dataset import bundled_path, read_motions

settings.register_profile(
  "ci", max_examples=40, derandomize=True, deadline=None, suppress_health_check=list(HealthCheck)
)
settings.register_profile("long", max_examples=10_000, deadline=None, suppress_health_check=list(HealthCheck))
PROFILE = os.environ.get("CHORJAX_FUZZ", "ci")
SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"

NUMBERS = ["nan", "inf", "-inf", "1e308", "-1e308", "1e30", "0", "-0", "99999999999999999999", "1e", "--1", "0x10", ""]


def _text_file(kind: str) -> tuple[str, dict[str, str]]:
  """``(the file's text, other files that go beside it)``: a real take of ``kind``, a few frames long."""
  if kind == "csv":
    lines = (bundled_path("cmu94") / "94_07_skeleton_3d.csv").read_text().splitlines()[:12]
    return "\n".join(lines) + "\n", {}
  if kind == "bvh":
    text = (SHARED / "bvh" / "bandai" / "dataset-1_dash_normal_001.bvh").read_text()
    head, motion = text.split("MOTION", 1)
    lines = motion.strip().splitlines()
    return head + "MOTION\nFrames: 8\n" + "\n".join([lines[1], *lines[2:10]]) + "\n", {}
  asf = (SHARED / "asfamc" / "cmu131" / "mjackson.asf").read_text()
  amc = (SHARED / "asfamc" / "cmu131" / "131_01.amc").read_text().splitlines()
  third = next(k for k, line in enumerate(amc) if line.strip() == "4")
  amc_text = "\n".join(amc[:third]) + "\n"
  if kind == "amc":
    return amc_text, {"mjackson.asf": asf}
  return asf, {"m.amc": amc_text}  # the ASF is what is mutated; read through its AMC


def _mutate(text: str, edits) -> str:
  lines = text.splitlines()
  for op, a, b, value in edits:
    if not lines:
      break
    i, j = int(a * len(lines)) % len(lines), int(b * len(lines)) % len(lines)
    words = lines[i].split()
    if op == "drop":
      del lines[i]
    elif op == "duplicate":
      lines.insert(i, lines[i])
    elif op == "swap_lines":
      lines[i], lines[j] = lines[j], lines[i]
    elif op == "truncate":
      lines = lines[: i + 1]
      lines[-1] = lines[-1][: int(b * len(lines[-1]))]
    elif op == "swap_tokens" and len(words) > 1:
      p, q = int(a * 997) % len(words), int(b * 997) % len(words)
      words[p], words[q] = words[q], words[p]
      lines[i] = " ".join(words)
    elif op == "number" and words:
      sep = "," if "," in lines[i] else " "
      cells = lines[i].split(sep)
      cells[int(b * 997) % len(cells)] = value
      lines[i] = sep.join(cells)
    elif op == "insert":
      lines.insert(i, value)
  return "\n".join(lines) + "\n"


EDITS = st.lists(
  st.tuples(
    st.sampled_from(["drop", "duplicate", "swap_lines", "truncate", "swap_tokens", "number", "number", "insert"]),
    st.floats(0, 1, exclude_max=True),
    st.floats(0, 1, exclude_max=True),
    st.sampled_from([*NUMBERS, "}", "{", "ROOT X", "MOTION", "begin", "end", ":bonedata", "1"]),
  ),
  min_size=1,
  max_size=5,
)


def _fresh(tmp_path_factory) -> Path:
  folder = tmp_path_factory.mktemp("fuzz")
  return folder


@pytest.mark.parametrize("kind", ["csv", "bvh", "amc", "asf"])
def test_mutated_text_files_are_read_or_refused_in_one_line(kind, tmp_path_factory):
  text, beside = _text_file(kind)

  @settings(settings.get_profile(PROFILE))
  @given(edits=EDITS)
  def check(edits):
    folder = _fresh(tmp_path_factory)
    mutated = _mutate(text, edits)
    if kind == "asf":
      (folder / "mjackson.asf").write_text(mutated)
      path = folder / "m.amc"
      path.write_text(beside["m.amc"])
    else:
      for name, content in beside.items():
        (folder / name).write_text(content)
      path = folder / f"m.{kind}"
      path.write_text(mutated)
    read_or_refused(path)
    shutil.rmtree(folder)

  assert read_or_refused(_write(tmp_path_factory, kind, text, beside)) is not None  # the unmutated file is read
  check()


def _write(tmp_path_factory, kind, text, beside) -> Path:
  folder = _fresh(tmp_path_factory)
  for name, content in beside.items():
    (folder / name).write_text(content)
  if kind == "asf":
    (folder / "mjackson.asf").write_text(text)
    return folder / "m.amc"
  (folder / f"m.{kind}").write_text(text)
  return folder / f"m.{kind}"


def test_mutated_sidecars_are_read_or_refused_in_one_line(tmp_path_factory):
  from chorjax.data.csv import sidecar_path, write_csv

  take = read_motions(SHARED / "bvh" / "bandai" / "dataset-1_dash_normal_001.bvh")[0]
  base = _fresh(tmp_path_factory) / "t.csv"
  write_csv(take.replace(positions=take.positions[:6]), base)
  side = sidecar_path(base).read_text()
  assert read_or_refused(base) is not None

  @settings(settings.get_profile(PROFILE))
  @given(edits=EDITS)
  def check(edits):
    folder = _fresh(tmp_path_factory)
    shutil.copy(base, folder / "t.csv")
    sidecar_path(folder / "t.csv").write_text(_mutate(side, edits))
    read_or_refused(folder / "t.csv")
    shutil.rmtree(folder)

  check()


def test_mutated_npz_samples_are_read_or_refused_in_one_line(tmp_path_factory):
  from chorjax.data.npz import write_npz
  from chorjax.data.skeletons import MPII16

  positions = read_motions(bundled_path("cmu94") / "94_07_skeleton_3d.csv")[0].positions[:10]
  good = write_npz(
    _fresh(tmp_path_factory) / "s.npz", positions[None], fps=30.0, skeleton=MPII16, up_axis="y", units="m", settings={}
  )
  with np.load(good) as z:
    arrays = {k: z[k] for k in z.files}
  meta = str(arrays["meta"])
  assert read_or_refused(good) is not None

  @settings(settings.get_profile(PROFILE))
  @given(
    edits=EDITS,
    values=st.lists(st.tuples(st.integers(0, positions.size - 1), st.sampled_from([np.nan, np.inf, 1e38, -1e38]))),
    shape=st.sampled_from([None, (10, 16, 3), (1, 10, 48), (1, 0, 16, 3), (2, 5, 16, 3), (1, 10, 15, 3)]),
    cut=st.one_of(st.none(), st.integers(0, 4000)),
  )
  def check(edits, values, shape, cut):
    folder = _fresh(tmp_path_factory)
    pos = arrays["positions"].copy().ravel()
    for k, v in values:
      pos[k] = v
    pos = pos.reshape(arrays["positions"].shape)
    if shape is not None:
      pos = np.resize(pos, shape)
    path = folder / "s.npz"
    np.savez(path, **{**arrays, "positions": pos, "meta": np.array(_mutate(meta, edits) if edits else meta)})
    if cut is not None:
      path.write_bytes(path.read_bytes()[:cut])
    read_or_refused(path)
    shutil.rmtree(folder)

  check()


def test_mutated_c3d_files_are_read_or_refused_in_one_line(tmp_path_factory):
  data = (SHARED / "c3d" / "ezc3d" / "Qualisys.c3d").read_bytes()
  assert read_or_refused(_copy_bytes(tmp_path_factory, data)) is not None

  @settings(settings.get_profile(PROFILE))
  @given(
    flips=st.lists(
      st.tuples(st.one_of(st.integers(0, 3071), st.integers(0, len(data) - 1)), st.integers(0, 255)), max_size=8
    ),
    floats=st.lists(st.tuples(st.integers(512, len(data) - 4), st.sampled_from([np.nan, np.inf, 1e38])), max_size=4),
    cut=st.one_of(st.none(), st.integers(0, len(data))),
  )
  def check(flips, floats, cut):
    raw = bytearray(data)
    for at, byte in flips:
      raw[at] = byte
    for at, value in floats:
      raw[at : at + 4] = np.float32(value).tobytes()
    path = _copy_bytes(tmp_path_factory, bytes(raw[:cut] if cut is not None else raw))
    read_or_refused(path)
    shutil.rmtree(path.parent)

  check()


def _copy_bytes(tmp_path_factory, data: bytes) -> Path:
  path = _fresh(tmp_path_factory) / "c.c3d"
  path.write_bytes(data)
  return path
