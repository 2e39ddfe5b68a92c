"""The documented examples work as written: every `.venv/bin/chorjax` line of the ``bash`` blocks of the
README and of the guides in docs/ runs (on a tiny model standing in for runs/quickstart, with toy training
sizes and short renders)."""

import re
import shlex
import shutil
from pathlib import Path

from helpers import GAN_NETWORKS, TINY

from chorjax import cli
from chorjax.data.dataset import bundled_path
from chorjax.training import train_and_evaluate

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
  for line in lines:
    args = tiny(shlex.split(line)[1:])
    try:
      code = cli.main(args)
    except SystemExit as e:  # argparse
      code = e.code
    assert code == 0, f"documented command failed: {line}"


def test_the_readme_has_examples_and_no_bare_chorjax_command():
  text = (ROOT / "README.md").read_text()
  assert len(readme_commands()) >= 8
  for block in re.findall(r"```bash\n(.*?)```", text, flags=re.S):
    for line in block.splitlines():
      assert not line.startswith("chorjax "), f"README runs a bare chorjax (not on PATH after the quick start): {line}"


def test_every_readme_command_runs(tmp_path, monkeypatch):
  """... and writes under runs/ (ignored by git): nothing lands beside the user's own files."""
  monkeypatch.chdir(tmp_path)
  run_documented(readme_commands(), tmp_path)
  assert {p.name for p in tmp_path.iterdir()} == {"configs", "chorjax", "my_phrase.csv", "runs"}


def test_the_guides_sweep_file_is_a_valid_sweep(tmp_path):
  from chorjax.config import load_config
  from chorjax.experiments import load_sweep, sweep_points

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
  from chorjax.experiments import load_sweep, sweep_points

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
  text = (ROOT / "README.md").read_text()
  section = text[text.index("## How well it dances") : text.index("## Commands")]
  assert re.search(r"^\| dataset", section, flags=re.M)
  assert "chorjax sweep experiments/dancers/sweep.toml" in section
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
