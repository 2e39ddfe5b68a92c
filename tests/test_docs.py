"""The documented examples work as written: every `.venv/bin/chorjax` line of the ``bash`` blocks of the
README and of the guides in docs/ runs (on a tiny model standing in for runs/quickstart, with toy training
sizes and short renders)."""

import json
import os
import re
import shlex
import shutil
import subprocess
from pathlib import Path

import pytest
from helpers import BLENDER_PYTHON, GAN_NETWORKS, TINY

from chorjax import cli
from chorjax.data.dataset import bundled_path
from chorjax.training.driver import train_and_evaluate

ROOT = Path(__file__).resolve().parents[1]
GUIDES = sorted((ROOT / "docs").rglob("*.md"))


def commands(page: Path) -> list[str]:
  blocks = re.findall(r"```bash\n(.*?)```", page.read_text(), flags=re.S)
  lines = [line.strip() for block in blocks for line in block.splitlines()]
  return [line for line in lines if line.startswith(".venv/bin/chorjax ")]


def readme_commands() -> list[str]:
  return commands(ROOT / "README.md")


def tiny(args: list[str]) -> list[str]:
  """The same command at toy sizes: tiny training (its calibration left to the documented `chorjax calibrate`
  line and tests/test_calibrate.py), at most 300 generated frames, 20 rendered."""
  if args[0] == "train":
    gan = GAN_NETWORKS if "configs/gan.toml" in args else []
    return [*args, *TINY, *gan, "log.tensorboard=false", "train.calibrate=false"]
  out = list(args)
  if "--frames" in out:
    i = out.index("--frames") + 1
    out[i] = str(min(int(out[i]), 300))
  if args[0] == "render" and any(a.endswith((".mp4", ".gif")) for a in args) and "--frames" not in out:
    out += ["--frames", "20", "--size", "320x240"]
  return out


def run_documented(lines: list[str], where: Path) -> None:
  """Runs ``lines`` in ``where`` (a copy of configs/, the package, my_phrase.csv, and a tiny runs/quickstart)."""
  from helpers import tiny_config

  shutil.copytree(ROOT / "configs", where / "configs")
  (where / "chorjax").symlink_to(ROOT / "chorjax")
  shutil.copy(bundled_path("cmu94") / "94_03_skeleton_3d.csv", where / "my_phrase.csv")
  train_and_evaluate(tiny_config("log.tensorboard=false", "train.eval_every=1"), where / "runs" / "quickstart")
  _run_in_order(lines)


def test_the_readme_has_examples_and_no_bare_chorjax_command():
  text = (ROOT / "README.md").read_text()
  assert len(readme_commands()) >= 8
  for block in re.findall(r"```bash\n(.*?)```", text, flags=re.S):
    for line in block.splitlines():
      assert not line.startswith("chorjax "), f"README runs a bare chorjax (not on PATH after the quick start): {line}"


# What a new user reads in their first hour, in order: the README (its quick start, then its commands), the
# guide for their own dancer, the export guide (ONNX, glTF, the Blender add-on).
FIRST_HOUR = ("README.md", "docs/guides/own-data.md", "docs/guides/export.md")


def quick_start_train() -> str:
  """The chorjax command that ends the README's one install command (``... && .venv/bin/chorjax train ...``)."""
  section = (ROOT / "README.md").read_text().split("## Quick start", 1)[1]
  install = re.search(r"```bash\n(.*?)\n```", section, flags=re.S).group(1).strip()
  assert install.startswith("python3 -m venv .venv && .venv/bin/pip install -e '.["), install
  return install.rsplit("&& ", 1)[1]


def test_the_first_hour_runs_in_order_in_one_fresh_clone(tmp_path, monkeypatch):
  """The README's quick start and commands, then the own-dancer guide's steps, then the export guide's (ONNX,
  glTF, the add-on), in that order in one copy of the repository's files, as a new user runs them (toy
  sizes); the add-on it wrote installs in headless Blender and imports the dance it drew. The README's
  commands write under runs/ (ignored by git): nothing lands beside the user's own files."""
  clone = tmp_path / "clone"
  tracked = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
  for name in filter(None, tracked.split("\0")):
    if (ROOT / name).is_file():
      (clone / name).parent.mkdir(parents=True, exist_ok=True)
      shutil.copy2(ROOT / name, clone / name)
  monkeypatch.chdir(clone)
  shutil.copy(bundled_path("cmu94") / "94_03_skeleton_3d.csv", clone / "my_phrase.csv")  # the README's phrase
  before = {p.name for p in clone.iterdir()}
  readme = [quick_start_train(), *commands(ROOT / "README.md")]
  _run_in_order(readme)
  assert {p.name for p in clone.iterdir()} == before | {"runs"}
  _run_in_order([line for page in FIRST_HOUR[1:] for line in commands(ROOT / page)])
  assert (clone / "runs" / "mine" / "samples" / "player.html").is_file() and (clone / "dance.glb").is_file()
  # the export guide's Blender step: its sample as .npz, imported with the add-on the guide wrote
  _run_in_order([".venv/bin/chorjax sample runs/quickstart -o dance.npz --frames 60"])
  if not BLENDER_PYTHON.exists():
    pytest.fail(f"Blender's Python is missing: .ci/run installs the bpy package into {BLENDER_PYTHON.parents[1]}")
  files = [str(clone / "chorjax_blender.zip"), str(clone / "dance.npz")]  # as Blender's file dialog gives them
  script = [str(BLENDER_PYTHON), str(ROOT / "tests" / "blender_addon.py"), *files, "-", "0"]
  env = {**os.environ, "BLENDER_USER_SCRIPTS": str(tmp_path / "blender")}
  done = subprocess.run(script, capture_output=True, text=True, timeout=300, env=env, cwd=clone)
  assert done.returncode == 0, done.stderr[-3000:]
  (line,) = [line for line in done.stdout.splitlines() if line.startswith("ADDON")]
  report = json.loads(line.removeprefix("ADDON"))
  assert report["import"] == ["FINISHED"] and len(report["imported"]) == 60


def _run_in_order(lines: list[str]) -> None:
  for line in lines:
    args = tiny(shlex.split(line)[1:])
    try:
      code = cli.main(args)
    except SystemExit as e:  # argparse
      code = e.code
    assert code == 0, f"documented command failed: {line}"


def test_the_guides_sweep_file_is_a_valid_sweep(tmp_path):
  from chorjax.config import load_config
  from chorjax.sweeps import load_sweep, sweep_points

  (example,) = re.findall(r"```toml\n(.*?)```", (ROOT / "docs" / "guides" / "sweeps.md").read_text(), flags=re.S)
  (tmp_path / "configs").symlink_to(ROOT / "configs")
  (tmp_path / "sweeps").mkdir()
  (tmp_path / "sweeps" / "s.toml").write_text(example)  # `base` is relative to the sweep file
  sweep = load_sweep(tmp_path / "sweeps" / "s.toml")
  points = sweep_points(sweep)
  assert len(points) == 2 * 3 * 1
  for _, overrides in points:
    load_config(tmp_path / "configs" / "quickstart.toml", overrides)


def test_every_experiment_sweep_loads_every_point():
  """The sweep files in experiments/ start from configs that change (the quickstart above all): each of their
  points must still be a valid config, or the experiment cannot be rerun as its README says."""
  from chorjax.config import load_config
  from chorjax.sweeps import load_sweep, sweep_points

  sweeps = [load_sweep(f) | {"file": f} for f in sorted(ROOT.glob("experiments/*/*.toml"))]
  sweeps = [s for s in sweeps if "base" in s]
  assert len(sweeps) >= 8
  for sweep in sweeps:
    for _, overrides in sweep_points(sweep):
      load_config(sweep["file"].parent / sweep["base"], overrides)


EXPERIMENT_PARTS = ("## Question", "## Reproduce", "## Answer", "## Pictures", "## Measured with")


def _shown_images(readme: Path) -> set[Path]:
  return {(readme.parent / m).resolve() for m in re.findall(r"!\[[^\]]*\]\(([^)\s]+\.png)\)", readme.read_text())}


def test_every_experiment_has_one_shape_and_every_figure_is_shown():
  """Each experiment's README says its question, how to reproduce it, its answer table, the pictures that show
  it, and what it was measured with; experiments/README.md indexes them all; no figure lies unshown."""
  folders = sorted(p for p in (ROOT / "experiments").iterdir() if p.is_dir() and not p.name.startswith(("_", ".")))
  index = (ROOT / "experiments" / "README.md").read_text()
  shown: set[Path] = set()
  for folder in folders:
    readme = folder / "README.md"
    assert readme.exists(), f"{folder.name} has no README"
    text = readme.read_text()
    positions = [text.find(part + "\n") for part in EXPERIMENT_PARTS]
    assert -1 not in positions and positions == sorted(positions), f"{folder.name}: parts {EXPERIMENT_PARTS}"
    answer = text[positions[2] : positions[3]]
    assert re.search(r"^\|.*\|\n\|[-| ]+\|$", answer, flags=re.M), f"{folder.name}: no table in its answer"
    images = _shown_images(readme)
    assert images, f"{folder.name} shows no picture"
    missing = [str(p) for p in images if not p.exists()]
    assert not missing, missing
    shown |= images
    assert f"({folder.name}/README.md)" in index, f"experiments/README.md does not index {folder.name}"
  unshown = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "experiments").rglob("*.png") if p.resolve() not in shown)
  assert not unshown, f"figures no README shows (delete them; git keeps them): {unshown}"


def test_the_readme_results_table_names_the_command_that_reproduces_it():
  from chorjax.sweeps import load_sweep

  text = (ROOT / "README.md").read_text()
  section = text[text.index("## How well it dances") : text.index("## Commands")]
  assert re.search(r"^\| dataset", section, flags=re.M)
  (sweep,) = re.findall(r"chorjax sweep (experiments/\w+/\w+\.toml)", section)
  assert load_sweep(ROOT / sweep)["base"].endswith("configs/quickstart.toml")  # the shipped recipe's benchmark
  for image in _shown_images(ROOT / "README.md"):
    assert image.exists(), image
  assert len(text.splitlines()) <= 200


def test_the_readmes_install_brings_every_extra_its_own_commands_need():
  """The quick start's one install serves the README's own commands: ``-o dance.glb`` and ``chorjax export``
  need the export extra, ``chorjax blender-addon`` and ``chorjax live`` the live one, videos and strips viz."""
  text = (ROOT / "README.md").read_text()
  extras = set(re.search(r"pip install -e '\.\[([a-z,]+)\]' && \.venv/bin/chorjax train", text).group(1).split(","))
  needs = {"export": ("chorjax export", ".glb"), "live": ("blender-addon", "chorjax live"), "viz": (".mp4", "--strip")}
  for extra, marks in needs.items():
    if any(m in text for m in marks):
      assert extra in extras, (extra, [m for m in marks if m in text])


def test_the_benchmarks_opening_table_is_the_one_its_results_files_make(monkeypatch):
  """BENCHMARKS.md opens with one table, one figure per cell with its machine, that ``benchmarks.opening``
  writes from the results files: edited by hand or left behind by a new measurement, it fails here."""
  monkeypatch.syspath_prepend(str(ROOT))
  from benchmarks import opening

  text = (ROOT / "BENCHMARKS.md").read_text()
  assert text.count(opening.START) == 1 and opening.table() in text
  table = opening.table().splitlines()[3:-1]
  assert len(table) >= 8 and all(row.count("|") == 6 and row.split("|")[-2].strip() for row in table)
