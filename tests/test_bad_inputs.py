"""Hostile but realistic input: every malformed file, impossible flag, broken config and damaged
checkpoint is a one-line error with exit code 2, no traceback, and nothing created, changed or left
behind. Plus property-based tests of the readers on random bytes and mutated real files."""

import io
import json
import os
import re
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
from helpers import read_or_refused, tiny_config
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from chorjax import cli
from chorjax.data.dataset import bundled_path, read_motions
from chorjax.errors import UserError
from chorjax.training.driver import train_and_evaluate

TINY_TRAIN = [
  "model.hidden_size=16",
  "model.num_layers=1",
  "train.batch_size=4",
  "data.seq_length=16",
  "train.num_steps=4",
  "train.checkpoint_every=2",
  "train.eval_every=0",
  "log.tensorboard=false",
  "log.progress=none",
  "sample.frames=20",
]
SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
CSV = bundled_path("cmu94") / "94_07_skeleton_3d.csv"
BVH = SHARED / "bvh" / "bandai" / "dataset-1_dash_normal_001.bvh"
ASF = SHARED / "asfamc" / "cmu131" / "mjackson.asf"
AMC = SHARED / "asfamc" / "cmu131" / "131_01.amc"


def snapshot(*roots) -> dict:
  """Every file under ``roots`` with its size and modification time (what "nothing changed" compares)."""
  return {
    str(p): (p.stat().st_size, p.stat().st_mtime_ns) for r in roots for p in sorted(Path(r).rglob("*")) if p.is_file()
  }


def refused(argv, capsys, *watch) -> str:
  """Runs the CLI; asserts exit 2, one stderr line, no traceback and ``watch`` untouched; returns stderr."""
  before = snapshot(*watch)
  try:
    code = cli.main([str(a) for a in argv])
  except SystemExit as e:  # a usage error (argparse)
    code = e.code
  err = capsys.readouterr().err
  assert code == 2, err
  assert re.match(r"chorjax[\w ]*: error: ", err) and err.count("\n") == 1 and "Traceback" not in err, err
  assert snapshot(*watch) == before
  return err


# ---------------------------------------------------------------- files: (name, how to make the file)


def _lines(path, n):
  return Path(path).read_text().splitlines()[:n]


def _csv(mutate):
  rows = _lines(CSV, 40)
  return "\n".join(mutate(rows)) + "\n"


def _cell(rows, row, col, value):
  cells = rows[row].split(",")
  cells[col] = value
  return [*rows[:row], ",".join(cells), *rows[row + 1 :]]


def _bvh(mutate):
  text = BVH.read_text()
  head, motion = text.split("MOTION", 1)
  lines = motion.strip().splitlines()
  return mutate(head, lines[:2], lines[2:])


def _bvh_value(value, frame=3, col=9):
  def mutate(head, header, frames):
    cells = frames[frame].split()
    cells[col] = value
    frames = [*frames[:frame], " ".join(cells), *frames[frame + 1 :]]
    return head + "MOTION\n" + "\n".join(header + frames) + "\n"

  return mutate


def _bvh_motion(header_lines, frames_of=lambda f: f):
  def mutate(head, header, frames):
    return head + "MOTION\n" + "\n".join([*header_lines, *frames_of(frames)]) + "\n"

  return mutate


def _short_last(frames):
  return [*frames[:-1], " ".join(frames[-1].split()[:-2])]


def _amc(mutate, frames=6):
  lines = AMC.read_text().splitlines()
  end = next(i for i, line in enumerate(lines) if line.strip() == str(frames + 1))
  return "\n".join(mutate(lines[:end])) + "\n"


def _amc_value(value, line=12, col=1):
  def mutate(lines):
    words = lines[line].split()
    words[col] = value
    return [*lines[:line], " ".join(words), *lines[line + 1 :]]

  return mutate


def _asf(old, new):
  text = ASF.read_text()
  assert old in text
  return text.replace(old, new, 1)


def _npz(positions=None, meta=None, drop=()):
  sk = read_motions(CSV)[0].skeleton
  pos = np.zeros((1, 20, sk.num_joints, 3), np.float32) if positions is None else positions
  m = {"fps": 30.0, "skeleton": sk.to_dict(), "up_axis": "y", "units": "m", "settings": {}}
  m.update(meta or {})
  arrays = {"positions": pos, "meta": np.array(json.dumps({k: v for k, v in m.items() if k not in drop}))}
  buf = io.BytesIO()
  np.savez(buf, **{k: v for k, v in arrays.items() if k not in drop})
  return buf.getvalue()


J = 16
FILES = {
  # CSV (the training layout)
  "csv-nan": ("t.csv", lambda: _csv(lambda r: _cell(r, 5, 7, "nan"))),
  "csv-inf": ("t.csv", lambda: _csv(lambda r: _cell(r, 5, 7, "inf"))),
  "csv-minus-inf": ("t.csv", lambda: _csv(lambda r: _cell(r, 9, 0, "-inf"))),
  "csv-huge": ("t.csv", lambda: _csv(lambda r: _cell(r, 5, 7, "1e30"))),
  "csv-text": ("t.csv", lambda: _csv(lambda r: _cell(r, 5, 7, "abc"))),
  "csv-columns": ("t.csv", lambda: _csv(lambda r: [*r[:3], r[3] + ",1.0", *r[4:]])),
  "csv-empty": ("t.csv", lambda: ""),
  "csv-blank": ("t.csv", lambda: "\n\n  \n"),
  "csv-binary": ("t.csv", lambda: bytes(range(256)) * 4),
  # BVH
  "bvh-nan": ("t.bvh", lambda: _bvh(_bvh_value("nan"))),
  "bvh-inf": ("t.bvh", lambda: _bvh(_bvh_value("inf"))),
  "bvh-huge": ("t.bvh", lambda: _bvh(_bvh_value("1e30"))),
  "bvh-text": ("t.bvh", lambda: _bvh(_bvh_value("x1"))),
  "bvh-short-line": ("t.bvh", lambda: _bvh(_bvh_motion(["Frames: 20", "Frame Time: 0.0333333"], _short_last))),
  "bvh-more-frames-declared": ("t.bvh", lambda: _bvh(_bvh_motion(["Frames: 99", "Frame Time: 0.0333333"]))),
  "bvh-fewer-frames-declared": ("t.bvh", lambda: _bvh(_bvh_motion(["Frames: 3", "Frame Time: 0.0333333"]))),
  "bvh-frame-time-zero": ("t.bvh", lambda: _bvh(_bvh_motion(["Frames: 20", "Frame Time: 0"]))),
  "bvh-frame-time-nan": ("t.bvh", lambda: _bvh(_bvh_motion(["Frames: 20", "Frame Time: nan"]))),
  "bvh-frame-time-inf": ("t.bvh", lambda: _bvh(_bvh_motion(["Frames: 20", "Frame Time: inf"]))),
  "bvh-no-motion": ("t.bvh", lambda: BVH.read_text().split("MOTION")[0]),
  "bvh-offset-nan": ("t.bvh", lambda: BVH.read_text().replace("OFFSET 15.7357 0 0", "OFFSET nan 0 0", 1)),
  "bvh-offset-text": ("t.bvh", lambda: BVH.read_text().replace("OFFSET 15.7357 0 0", "OFFSET a b c", 1)),
  "bvh-offset-huge": ("t.bvh", lambda: BVH.read_text().replace("OFFSET 15.7357 0 0", "OFFSET 1e300 0 0", 1)),
  "bvh-truncated-hierarchy": ("t.bvh", lambda: BVH.read_text()[:400]),
  "bvh-empty": ("t.bvh", lambda: ""),
  "bvh-binary": ("t.bvh", lambda: b"\xff\xfe\x00BVH" * 100),
  # ASF/AMC (the ASF beside the AMC)
  "amc-nan": ("t.amc", lambda: _amc(_amc_value("nan"))),
  "amc-inf": ("t.amc", lambda: _amc(_amc_value("-inf"))),
  "amc-huge": ("t.amc", lambda: _amc(_amc_value("1e30"))),
  "amc-text": ("t.amc", lambda: _amc(_amc_value("x"))),
  "amc-truncated": ("t.amc", lambda: _amc(lambda lines: lines[:-5])),
  "amc-unknown-bone": ("t.amc", lambda: _amc(lambda lines: [*lines[:12], "tail 1 2 3", *lines[12:]])),
  "amc-values-before-frame": ("t.amc", lambda: _amc(lambda lines: ["root 0 0 0 0 0 0", *lines])),
  "amc-value-count": ("t.amc", lambda: _amc(lambda lines: [*lines[:12], lines[12] + " 4.0", *lines[13:]])),
  "amc-no-frames": ("t.amc", lambda: ":FULLY-SPECIFIED\n:DEGREES\n"),
  "asf-length-nan": ("t.amc", lambda: _amc(lambda lines: lines), lambda: _asf("length 7.28989", "length nan")),
  "asf-direction-text": (
    "t.amc",
    lambda: _amc(lambda lines: lines),
    lambda: _asf("direction 0.34202 -0.939693 0", "direction 0.34202 one 0"),
  ),
  "asf-no-hierarchy": ("t.amc", lambda: _amc(lambda lines: lines), lambda: _asf(":hierarchy", ":nothing")),
  # NPZ (chorjax samples)
  "npz-not-zip": ("t.npz", lambda: b"not a zip file"),
  "npz-no-meta": ("t.npz", lambda: _npz(drop=("meta",))),
  "npz-no-positions": ("t.npz", lambda: _npz(drop=("positions",))),
  "npz-no-skeleton": ("t.npz", lambda: _npz(drop=("skeleton",))),
  "npz-2d-positions": ("t.npz", lambda: _npz(np.zeros((20, 3 * J), np.float32))),
  "npz-joint-count": ("t.npz", lambda: _npz(np.zeros((1, 20, J - 1, 3), np.float32))),
  "npz-zero-frames": ("t.npz", lambda: _npz(np.zeros((1, 0, J, 3), np.float32))),
  "npz-nan": ("t.npz", lambda: _npz(np.full((1, 20, J, 3), np.nan, np.float32))),
  "npz-huge": ("t.npz", lambda: _npz(np.full((1, 20, J, 3), 1e30, np.float32))),
  "npz-fps-nan": ("t.npz", lambda: _npz(meta={"fps": float("nan")})),
  "npz-bad-skeleton": ("t.npz", lambda: _npz(meta={"skeleton": {"name": "x"}})),
  # C3D
  "c3d-empty": ("t.c3d", lambda: b""),
  "c3d-bad-header": ("t.c3d", lambda: b"\x02\x00" + b"\x00" * 600),
  "c3d-garbage": ("t.c3d", lambda: b"\x02\x50" + bytes(range(256)) * 8),
  "c3d-truncated": ("t.c3d", lambda: (SHARED / "c3d" / "ezc3d" / "Optotrak.c3d").read_bytes()),
  "c3d-cut": ("t.c3d", lambda: (SHARED / "c3d" / "cmu01" / "01_01.c3d").read_bytes()[:3000]),
}


def _make(tmp_path, case) -> Path:
  name, content, *asf = FILES[case]
  path = tmp_path / "in" / name
  path.parent.mkdir()
  body = content()
  path.write_bytes(body.encode() if isinstance(body, str) else body)
  if name.endswith(".amc"):
    (path.parent / "mjackson.asf").write_text(asf[0]() if asf else ASF.read_text())
  return path


@pytest.mark.parametrize("case", sorted(FILES))
def test_every_reader_refuses_a_bad_file_in_one_line(case, tmp_path, capsys):
  path = _make(tmp_path, case)
  err = refused(["data", "info", path], capsys, tmp_path)
  assert str(path.parent) in err  # names the file (or, for a broken skeleton, the ASF beside it)


@pytest.mark.parametrize("case", ["csv-nan", "bvh-huge", "amc-truncated", "npz-nan", "c3d-cut"])
def test_convert_writes_nothing_from_a_bad_file(case, tmp_path, capsys):
  path = _make(tmp_path, case)
  out = tmp_path / "out"
  refused(["data", "convert", path, "-o", out], capsys, tmp_path)
  assert not out.exists()


def test_the_good_files_those_cases_are_made_from_are_read(tmp_path):
  for path in (CSV, BVH, AMC):
    (m,) = read_motions(path)
    assert m.num_frames > 0 and np.isfinite(m.positions).all()


# ---------------------------------------------------------------- flags, configs, commands


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
  w = tmp_path_factory.mktemp("run")
  train_and_evaluate(tiny_config("train.num_steps=4", "train.checkpoint_every=2", "log.tensorboard=false"), w)
  return w


SAMPLE_FLAGS = {
  "frames-0": ["--frames", "0"],
  "frames-negative": ["--frames", "-5"],
  "num-0": ["--num", "0"],
  "num-negative": ["--num", "-2"],
  "pi-negative": ["--set", "sample.pi_temperature=-1"],
  "pi-inf": ["--set", "sample.pi_temperature=inf"],
  "pi-nan": ["--set", "sample.pi_temperature=nan"],
  "sigma-nan": ["--sigma-temperature", "nan"],
  "sigma-negative": ["--sigma-temperature", "-1"],
  "smoothing-1": ["--set", "sample.noise_smoothing=1"],
  "crossfade-big": ["--set", "sample.crossfade=1.5"],
  "persistence-negative": ["--set", "sample.persistence=-1"],
  "pace-negative": ["--pace", "-1"],
  "pace-nan": ["--pace", "nan"],
  "checkpoint-missing": ["--checkpoint", "999"],
  "checkpoint-word": ["--checkpoint", "newest"],
  "mix-malformed": ["--mix", "3:x"],
  "mix-negative": ["--mix", "1:-1,2:2"],
  "motion-unknown": ["--motion", "99"],
  "prime-missing": ["--prime", "nowhere.csv"],
  "prime-range": ["--prime", f"{CSV}:a:b"],
  "output-suffix": ["-o", "OUT/x.xyz"],
  "output-dir": ["-o", "OUT"],
  "size-odd": ["--size", "0x0"],
  "frames-huge": ["--frames", "1000000000"],  # sizes are estimated before allocating: the flag is named
  "num-huge": ["--num", "10000000"],
}


@pytest.mark.parametrize("case", sorted(SAMPLE_FLAGS))
def test_sample_refuses_impossible_flags(case, run_dir, tmp_path, capsys):
  flags = [str(tmp_path) if f == "OUT" else f.replace("OUT", str(tmp_path)) for f in SAMPLE_FLAGS[case]]
  out = [] if "-o" in flags else ["-o", tmp_path / "s.csv"]
  if case == "size-odd":
    out = ["-o", tmp_path / "s.mp4"]
  err = refused(["sample", run_dir, *out, *flags], capsys, tmp_path, run_dir)
  if case == "prime-range":
    assert "START and LEN must be whole numbers" in err


EVAL_FLAGS = {
  "num-0": ["--num", "0"],
  "frames-0": ["--frames", "0"],
  "frames-short": ["--frames", "10"],
  "data-missing": ["--data", "nowhere/"],
  "sigma-inf": ["--sigma-temperature", "inf"],
  "checkpoint-missing": ["--checkpoint", "7"],
  "output-dir": ["-o", "OUT"],
  "frames-huge": ["--frames", "1000000000"],
}


@pytest.mark.parametrize("case", sorted(EVAL_FLAGS))
def test_eval_refuses_impossible_flags(case, run_dir, tmp_path, capsys):
  flags = [str(tmp_path) if f == "OUT" else f for f in EVAL_FLAGS[case]]
  data = [] if "--data" in flags else ["--data", "cmu94"]
  refused(["eval", run_dir, *data, "--frames", "200", "--num", "1", *flags], capsys, tmp_path, run_dir)


def _toml(tmp_path, text):
  p = tmp_path / "c.toml"
  p.write_text(text)
  return p


COMMANDS = {
  "sample-no-run": lambda t, r: ["sample", t / "nowhere", "-o", t / "s.csv"],
  "sample-run-is-file": lambda t, r: ["sample", CSV, "-o", t / "s.csv"],
  "eval-no-run": lambda t, r: ["eval", t / "nowhere", "--data", "cmu94"],
  "render-missing": lambda t, r: ["render", t / "nowhere.csv", "-o", t / "x.gif"],
  "render-frames-0": lambda t, r: ["render", CSV, "-o", t / "x.gif", "--frames", "0"],
  "render-suffix": lambda t, r: ["render", CSV, "-o", t / "x.doc"],
  "render-size-huge": lambda t, r: ["render", CSV, "-o", t / "x.mp4", "--size", "100000x100000"],
  "render-poses-huge": lambda t, r: ["render", CSV, "-o", t / "x.png", "--strip", "--poses", "100000"],
  "metrics-window-0": lambda t, r: ["metrics", CSV, "--data", "cmu94", "--window", "0"],
  "metrics-splits-0": lambda t, r: ["metrics", CSV, "--data", "cmu94", "--splits", "0"],
  "metrics-splits-huge": lambda t, r: ["metrics", CSV, "--data", "cmu94", "--splits", "1000000"],
  "train-batch-huge": lambda t, r: [
    "train",
    "configs/quickstart.toml",
    "train.batch_size=1000000000",
    "--workdir",
    t / "w",
  ],
  "train-hidden-huge": lambda t, r: [
    "train",
    "configs/quickstart.toml",
    "model.hidden_size=100000000000000000000",
    "--workdir",
    t / "w",
  ],
  "metrics-missing": lambda t, r: ["metrics", t / "nowhere.csv", "--data", "cmu94"],
  "compare-missing": lambda t, r: ["compare", t / "nowhere", "-o", t / "r.md"],
  "sweep-missing": lambda t, r: ["sweep", t / "nowhere.toml"],
  "sweep-unknown-key": lambda t, r: ["sweep", _toml(t, 'name = "s"\nbase = "x"\nroot = "r"\ngird = {}\n')],
  "sweep-unknown-grid-key": lambda t, r: [
    "sweep",
    _toml(t, 'name="s"\nbase="x"\nroot="r"\n[grid]\n"train.sed"=[1]\n'),
  ],
  "config-unknown-key": lambda t, r: ["config", "show", "configs/quickstart.toml", "model.hidden_sise=3"],
  "config-bad-type": lambda t, r: ["config", "show", "configs/quickstart.toml", "model.hidden_size=big"],
  "config-lr-nan": lambda t, r: ["config", "show", "configs/quickstart.toml", "optim.lr=nan"],
  "config-missing": lambda t, r: ["config", "show", t / "nowhere.toml"],
  "config-syntax": lambda t, r: ["config", "show", _toml(t, "[model\nhidden_size = 3\n")],
  "config-unknown-table": lambda t, r: ["config", "show", _toml(t, "[modle]\nhidden_size = 3\n")],
  "train-unknown-key": lambda t, r: ["train", "configs/quickstart.toml", "train.num_step=3", "--workdir", t / "w"],
  "train-negative-steps": lambda t, r: ["train", "configs/quickstart.toml", "train.num_steps=-3", "--workdir", t / "w"],
  "train-workdir-is-file": lambda t, r: ["train", "configs/quickstart.toml", "--workdir", CSV],
  "train-changed-config": lambda t, r: ["train", "configs/quickstart.toml", "--workdir", r],
  "data-info-missing": lambda t, r: ["data", "info", t / "nowhere.bvh"],
  "data-info-empty-dir": lambda t, r: ["data", "info", t],
  "data-convert-bad-scale": lambda t, r: ["data", "convert", CSV, "-o", t / "o", "--scale", "nan"],
  "data-convert-bad-fps": lambda t, r: ["data", "convert", CSV, "-o", t / "o", "--fps", "0"],
}


@pytest.mark.parametrize("case", sorted(COMMANDS))
def test_commands_refuse_bad_paths_configs_and_values(case, run_dir, tmp_path, capsys, monkeypatch):
  monkeypatch.chdir(Path(__file__).resolve().parents[1])
  argv = COMMANDS[case](tmp_path, run_dir)
  watch = [tmp_path, run_dir] if not case.startswith("config") else [tmp_path]
  err = refused(argv, capsys, *watch)
  assert not (tmp_path / "w").exists() and not (tmp_path / "o").exists()
  if "unknown-key" in case:
    assert "did you mean" in err


# ---------------------------------------------------------------- damaged checkpoints

DAMAGE = {
  "meta-empty": lambda d: (d / "meta" / "metadata").write_text(""),
  "meta-missing": lambda d: (d / "meta" / "metadata").unlink(),
  "meta-not-object": lambda d: (d / "meta" / "metadata").write_text("[1, 2]"),
  "meta-no-config": lambda d: (d / "meta" / "metadata").write_text('{"id_map": {}}'),
  "params-metadata-empty": lambda d: (d / "params" / "_METADATA").write_text(""),
  "params-data-truncated": lambda d: [p.write_bytes(p.read_bytes()[:10]) for p in (d / "params").rglob("d/*")],
  "params-manifest-cut": lambda d: (d / "params" / "manifest.ocdbt").write_bytes(b"xx"),
}


@pytest.mark.parametrize("case", sorted(DAMAGE))
@pytest.mark.parametrize("command", ["sample", "eval"])
def test_a_damaged_checkpoint_is_named_and_an_intact_one_suggested(case, command, run_dir, tmp_path, capsys):
  work = tmp_path / "run"
  shutil.copytree(run_dir, work)
  DAMAGE[case](work / "checkpoints" / "4")
  tail = ["-o", tmp_path / "s.csv"] if command == "sample" else ["--data", "cmu94", "--frames", "200"]
  err = refused([command, work, *tail], capsys, tmp_path)
  assert f"checkpoints/4/{'params' if 'params' in case else 'meta'}" in err
  assert "use --checkpoint 2 (intact)" in err


def test_training_resumes_from_the_newest_intact_checkpoint(run_dir, tmp_path, capsys):
  work = tmp_path / "run"
  shutil.copytree(run_dir, work)
  DAMAGE["params-data-truncated"](work / "checkpoints" / "4")
  cfg = tiny_config("train.num_steps=6", "train.checkpoint_every=2", "log.tensorboard=false")
  train_and_evaluate(cfg, work)
  err = capsys.readouterr().err
  assert "checkpoints/4/params" in err and "resuming from step 2" in err and err.count("warning") == 1
  assert sorted(int(p.name) for p in (work / "checkpoints").iterdir() if p.name.isdigit())[-1] == 6
  assert (work / "checkpoints-damaged" / "4").is_dir()  # kept for the user, not deleted
  lines = [json.loads(line) for line in (work / "metrics.jsonl").read_text().splitlines()]
  assert [r["step"] for r in lines if "train_loss" in r] == sorted({r["step"] for r in lines if "train_loss" in r})


def test_training_never_silently_restarts_when_every_checkpoint_is_damaged(run_dir, tmp_path, capsys):
  work = tmp_path / "run"
  shutil.copytree(run_dir, work)
  for step in ("2", "4"):
    DAMAGE["meta-empty"](work / "checkpoints" / step)
  cfg = tiny_config("train.num_steps=6", "train.checkpoint_every=2", "log.tensorboard=false")
  with pytest.raises(UserError, match="no intact checkpoint"):
    train_and_evaluate(cfg, work)


def _cli_with_small_files(argv):
  """The CLI in a subprocess (from the repository root) where no file may grow beyond 10 kB."""
  import subprocess
  import sys

  code = (
    "import resource, signal, sys; signal.signal(signal.SIGXFSZ, signal.SIG_IGN); "
    "resource.setrlimit(resource.RLIMIT_FSIZE, (10_000, 10_000)); from chorjax.cli import main; "
    f"sys.exit(main({argv!r}))"
  )
  root = Path(__file__).resolve().parents[1]
  # no cache writes to fail first: neither compiled programs nor (below) the takes read
  env = {k: v for k, v in os.environ.items() if k != "JAX_COMPILATION_CACHE_DIR"} | {"CHORJAX_COMPILE_CACHE": "off"}
  return subprocess.run([sys.executable, "-c", code], cwd=root, env=env, capture_output=True, text=True, timeout=300)


def test_a_checkpoint_that_cannot_be_written_is_one_line_and_leaves_no_partial_step(tmp_path):
  """A real failing write, without root: files beyond 10 kB fail (RLIMIT_FSIZE, as a full disk would)."""

  work = tmp_path / "w"
  argv = ["train", "configs/quickstart.toml", *TINY_TRAIN, "data.cache=off", "--workdir", str(work)]
  done = _cli_with_small_files(argv)
  assert done.returncode == 2, done.stderr[-2000:]
  assert done.stderr.splitlines() == [
    f"chorjax: error: {work}/checkpoints: the checkpoint at step 2 could not be written (File too large)"
  ]
  assert not list((work / "checkpoints").iterdir())  # nothing half written


def test_a_sample_that_cannot_be_written_is_one_line_and_leaves_nothing(run_dir, tmp_path):
  """As above, for `sample` (a CSV of 3,000 frames is far beyond 10 kB)."""

  out = tmp_path / "out" / "s.csv"
  done = _cli_with_small_files(["sample", str(run_dir), "-o", str(out), "--frames", "3000"])
  assert done.returncode == 2, done.stderr[-2000:]
  assert len(done.stderr.splitlines()) == 1 and "File too large" in done.stderr, done.stderr[-2000:]
  assert not list(out.parent.iterdir())  # no half-written sample, no temporary


def test_a_temporary_file_left_by_a_killed_write_is_cleaned_at_the_next_write(tmp_path):
  from chorjax.errors import atomic_write

  stale = tmp_path / ".s.tmp999999999.abcd.csv"  # a pid that cannot be alive
  stale.write_text("half")
  mine = tmp_path / ".other.tmp999999999.x.csv"  # another target's temporary is left to that target's write
  mine.write_text("half")
  atomic_write(tmp_path / "s.csv", lambda p: p.write_text("whole"))
  assert (tmp_path / "s.csv").read_text() == "whole"
  assert not stale.exists() and mine.exists()


# ---------------------------------------------------------------- property-based: the readers


SUFFIXES = [".csv", ".bvh", ".npz", ".c3d", ".amc"]


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.binary(max_size=600), suffix=st.sampled_from(SUFFIXES))
def test_random_bytes_are_read_or_refused_in_one_line(tmp_path, data, suffix):
  path = tmp_path / f"r{suffix}"
  path.write_bytes(data)
  if suffix == ".amc":
    (tmp_path / "mjackson.asf").write_text(ASF.read_text())
  read_or_refused(path)


def _real(suffix) -> bytes:
  if suffix == ".csv":
    return "\n".join(_lines(CSV, 30)).encode() + b"\n"
  if suffix == ".bvh":
    return _bvh(lambda h, hd, f: h + "MOTION\n" + "\n".join([*hd, *f]) + "\n").encode()
  return _amc(lambda lines: lines).encode()


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
  suffix=st.sampled_from([".csv", ".bvh", ".amc"]),
  edits=st.lists(
    st.tuples(st.floats(0, 1), st.sampled_from([b"", b"nan", b"1e30", b"-", b"\n", b" ", b"x", b"{", b"9" * 12])),
    min_size=1,
    max_size=4,
  ),
  cut=st.floats(0.05, 1.0),
)
def test_mutated_real_files_are_read_or_refused_in_one_line(tmp_path, suffix, edits, cut):
  data = _real(suffix)
  for where, insert in edits:
    i = int(where * len(data))
    data = data[:i] + insert + data[i + 1 :]
  path = tmp_path / f"m{suffix}"
  path.write_bytes(data[: max(int(cut * len(data)), 1)])
  if suffix == ".amc":
    (tmp_path / "mjackson.asf").write_text(ASF.read_text())
  read_or_refused(path)


def test_a_zip_that_is_not_a_sample_is_refused(tmp_path):
  path = tmp_path / "z.npz"
  with zipfile.ZipFile(path, "w") as z:
    z.writestr("positions.npy", b"garbage")
  assert read_or_refused(path) is None


def test_the_cli_drops_only_orbax_leftovers_among_unraisable_exceptions():
  from types import SimpleNamespace

  seen = []
  hook = cli._quiet_closed_loop(seen.append)
  closed = SimpleNamespace(exc_value=RuntimeError("Event loop is closed"), object=None)
  orbax_code = SimpleNamespace(co_filename="/x/orbax/checkpoint/_src/serialization/serialization.py")
  abandoned = SimpleNamespace(exc_value=GeneratorExit(), object=SimpleNamespace(cr_code=orbax_code))
  ours = SimpleNamespace(exc_value=RuntimeError("something else"), object=None)
  other_coroutine = SimpleNamespace(exc_value=GeneratorExit(), object=SimpleNamespace(cr_code=None))
  for info in (closed, abandoned, ours, other_coroutine):
    hook(info)
  assert seen == [ours, other_coroutine]
