"""The format registry (``chorjax.data.formats``): every format declared once, and a new one is one registration that
``chorjax data info``, ``sample -o``, ``render`` and the help then handle."""

import json
from pathlib import Path

import numpy as np
import pytest
from helpers import tiny_config

from chorjax import cli
from chorjax.data import formats
from chorjax.data.dataset import bundled_path
from chorjax.data.motion import Motion, Skeleton
from chorjax.training.driver import train_and_evaluate

TAKE = bundled_path("cmu94") / "94_07_skeleton_3d.csv"


def _read_toy(path: Path, reading: formats.Reading) -> list:
  """A toy format: JSON with the rate, the skeleton and every frame's joints."""
  d = json.loads(path.read_text())
  return [
    Motion(np.asarray(d["frames"], np.float32), d["fps"], Skeleton.from_dict(d["skeleton"]), "-y", name=path.stem)
  ]


def _write_toy(motions, paths, writing: formats.Writing) -> list:
  for m, p in zip(motions, paths):
    p.write_text(json.dumps({"fps": m.fps, "skeleton": m.skeleton.to_dict(), "frames": m.positions.tolist()}))
  return paths


def _draw_toy(motions, out: Path, drawing: formats.Drawing) -> Path:
  """The toy 'picture': each motion's mean height per frame, one line each."""
  out.write_text("\n".join(" ".join(f"{h:.3f}" for h in m.positions[..., 1].mean(1)) for m in motions))
  return out


@pytest.fixture
def toy():
  fmt = formats.register(formats.Format("toy", (".toy",), read=_read_toy, write=_write_toy, draw=_draw_toy))
  yield fmt
  formats.unregister(fmt)


def test_the_shipped_formats_are_declared_once_with_their_roles():
  assert formats.suffixes("read") == (".csv", ".npz", ".bvh", ".amc", ".c3d")
  assert formats.suffixes("write") == (".csv", ".npz", ".bvh", ".glb", ".html")
  assert formats.suffixes("draw") == (".png", ".gif", ".mp4", ".html")
  with pytest.raises(ValueError, match="already BVH's"):
    formats.register(formats.Format("another", (".bvh",)))


def test_a_new_format_is_read_written_and_drawn_by_the_commands(toy, tmp_path, capsys):
  """One registration: ``sample -o OUT.toy`` writes it (K files for K dancers), ``data info`` and ``render``
  read it, ``render -o OUT.toy`` draws into it, and the help lists it; unregistered, it is refused again."""
  run = tmp_path / "run"
  train_and_evaluate(tiny_config("train.num_steps=2", "log.tensorboard=false", "train.calibrate=false"), run)
  assert cli.main(["sample", str(run), "--frames", "40", "--num", "2", "-o", str(tmp_path / "s.toy")]) == 0
  written = sorted(p.name for p in tmp_path.glob("s_*.toy"))
  assert written == ["s_0.toy", "s_1.toy"]
  capsys.readouterr()
  assert cli.main(["data", "info", str(tmp_path / "s_0.toy")]) == 0
  assert "40" in capsys.readouterr().out  # its frames, read back
  assert cli.main(["render", str(tmp_path / "s_1.toy"), str(TAKE), "-o", str(tmp_path / "both.html")]) == 0
  assert (tmp_path / "both.html").stat().st_size > 0
  assert cli.main(["render", str(TAKE), "-o", str(tmp_path / "heights.toy")]) == 0
  heights = np.asarray((tmp_path / "heights.toy").read_text().split(), float)
  assert heights.size == len(TAKE.read_text().splitlines()) and np.ptp(heights) > 0
  assert ".toy" in _render_help(capsys)  # the help asks the registry
  # the API: read_motion, Motion.write and render read and write it alike
  import chorjax

  taken = chorjax.read_motion(tmp_path / "s_0.toy")
  assert taken.positions.shape == (40, 16, 3)
  again = taken.write(tmp_path / "again.toy")
  np.testing.assert_allclose(chorjax.read_motion(again).positions, taken.positions, atol=1e-6)
  assert chorjax.api.render([str(again)], tmp_path / "again_heights.toy").read_text().count(" ") == 39
  formats.unregister(toy)
  assert cli.main(["data", "info", str(tmp_path / "s_0.toy")]) == 2
  assert ".toy" in capsys.readouterr().err


def _render_help(capsys) -> str:
  with pytest.raises(SystemExit):
    cli.main(["render", "--help"])
  return capsys.readouterr().out


def test_the_formats_guide_lists_what_the_registry_declares():
  """docs/guides/formats.md's table: a row per registered format with its suffixes and what it can do."""
  text = (Path(__file__).resolve().parents[1] / "docs" / "guides" / "formats.md").read_text()
  cells = ([c.strip() for c in line.strip("|").split("|")] for line in text.splitlines() if line.startswith("| "))
  rows = {r[0]: r[1:5] for r in cells}
  shipped = {f.name: f for f in formats.FORMATS.values()}
  assert set(shipped) <= set(rows), set(shipped) - set(rows)
  for name, fmt in shipped.items():
    suffixes, *roles = rows[name]
    assert suffixes == ", ".join(f"`{s}`" for s in fmt.suffixes), name
    assert roles == ["yes" if getattr(fmt, r) else "-" for r in ("read", "write", "draw")], name
