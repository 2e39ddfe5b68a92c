"""examples/quickstart.ipynb runs top to bottom on a tiny model, shows what it says, and its HTML export
plays the dancer in a browser; the API reference builds without warnings."""

import json
from pathlib import Path

import imageio.v3 as iio
import numpy as np
from helpers import TINY, headless

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOK = ROOT / "examples" / "quickstart.ipynb"


def _outputs(cell) -> str:
  """Everything a code cell showed: printed text and the HTML of displayed objects."""
  parts = []
  for out in cell.get("outputs", []):
    parts.append(out.get("text", ""))
    parts.append(out.get("data", {}).get("text/plain", ""))
    parts.append(out.get("data", {}).get("text/html", ""))
  return "\n".join(parts)


def test_the_notebook_runs_and_its_export_plays_the_dancer(tmp_path, monkeypatch):
  import nbformat
  from nbclient import NotebookClient
  from nbconvert import HTMLExporter

  overrides = [o for o in TINY if not o.startswith("log.progress")] + [
    "train.num_steps=3",
    "train.calibrate=false",  # five tiny calibrations would add minutes; tests/test_calibrate.py has its own
    "log.tensorboard=false",
    "sample.frames=20",
  ]
  monkeypatch.setenv("CHORJAX_NOTEBOOK_OVERRIDES", json.dumps(overrides))
  monkeypatch.setenv("CHORJAX_NOTEBOOK_RUNS", str(tmp_path / "runs"))
  nb = nbformat.read(NOTEBOOK, as_version=4)
  NotebookClient(
    nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(NOTEBOOK.parent)}}
  ).execute()
  shown = {i: _outputs(c) for i, c in enumerate(nb.cells) if c.cell_type == "code"}
  text = "\n".join(shown.values())
  assert "94_01_skeleton_3d: 830 frames at 30 fps, 16 joints" in text
  assert any("image/png" in o.get("data", {}) for c in nb.cells for o in c.get("outputs", []))  # the filmstrip
  assert text.count("<iframe srcdoc=") == 2  # both players, embedded in the cell outputs
  assert "sample: (300, 16, 3)" in text and "trained to step 3 on 9 takes, held out: 94_10_skeleton_3d" in text
  assert "jitter" in text and "root_travel" in text
  assert "mdn: movement in the last segment" in text and "over 2 seeds" in text and "mse:" in text
  assert "Error" not in text and "Traceback" not in text
  assert "\rstep 3/3 loss" in text  # training's progress: one line rewritten in place (log.progress auto)

  page = tmp_path / "quickstart.html"
  page.write_text(HTMLExporter().from_notebook_node(nb)[0], encoding="utf-8")
  shots = []
  for budget in (1500, 3500):  # two moments of the page's own clock: the players play by themselves
    shot = tmp_path / f"shot{budget}.png"
    flags = ["--window-size=1280,4000", f"--virtual-time-budget={budget}", f"--screenshot={shot}"]
    headless(tmp_path / "profile", f"file://{page}", *flags)
    shots.append(iio.imread(shot)[..., :3].astype(int))
  changed = int((np.abs(shots[0] - shots[1]).sum(-1) > 30).sum())
  assert changed > 200, changed  # stick figures moved between the two moments
