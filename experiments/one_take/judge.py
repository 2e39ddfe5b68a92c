"""The one-take benchmark's figures: each run of runs/one_take/ (the recipe's seeds of sweep.toml, the patch
family's, the quickstart's) judged against the take it learned (``chorjax eval RUN --data TAKE``: movement,
jitter, speed, and the single-take measures: coverage, global, local and inter-sample diversity) and, where
the dancer has other takes, against those (``--data OTHER...``: FID_g over the training slice's own), 2
sampling seeds x 10,000 frames each; written to RUN/one_take.json and RUN/other_takes.json, their figures to
results.json beside this file (the table rebuilds from it without the runs).

  python experiments/one_take/judge.py runs/one_take/one-*           # evaluate (skips what is there)
  python experiments/one_take/judge.py --patch                       # index the patch family on each take
  python experiments/one_take/judge.py --table                       # the table, as markdown
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
TAKES = ROOT / "runs" / "one_take" / "takes"
SHARED = ROOT.parent / "shared" / "data"
CMU94 = ROOT / "chorjax" / "data" / "bundled" / "cmu94"
# the dancer's other takes (none for the Bandai dance: its other takes are a walk and a dash)
OTHER = {
  "cmu94": sorted(str(p) for p in CMU94.glob("*.csv") if not p.name.startswith("94_05")),
  "salsa": sorted(str(p) for p in (SHARED / "aclstm" / "salsa").glob("*.bvh") if p.stem not in ("09", "24")),
  "martial": sorted(str(p) for p in (SHARED / "aclstm" / "martial").glob("*.bvh") if p.stem != "06"),
}
CHORJAX = str(Path(sys.executable).parent / "chorjax")
EVAL = ["--frames", "10000", "--num", "1", "--seeds", "0", "1"]


def take_of(run: Path) -> Path:
  return Path(json.loads((run / "config.json").read_text())["data"]["dataset"])


def evaluate(run: Path) -> None:
  take = take_of(run)
  dancer = take.name.split("_")[0]
  if not (run / "one_take.json").exists():
    subprocess.run(
      [CHORJAX, "eval", str(run), "--data", str(take), *EVAL, "-o", str(run / "one_take.json")], check=True
    )
  if dancer in OTHER and not (run / "other_takes.json").exists():
    subprocess.run(
      [CHORJAX, "eval", str(run), "--data", *OTHER[dancer], *EVAL, "-o", str(run / "other_takes.json")], check=True
    )


def patch(take: Path) -> Path:
  run = ROOT / "runs" / "one_take" / f"patch-{take.stem}"
  if not (run / "config.json").exists():
    subprocess.run(
      [
        CHORJAX,
        "train",
        "configs/patch.toml",
        f"data.dataset={take}",
        "data.val_takes=[]",
        "data.resample_fps=30.0",
        "--workdir",
        str(run),
      ],
      check=True,
      cwd=ROOT,
    )
  return run


def mean(v):
  return v["mean"] if isinstance(v, dict) else v


# the figures against the take, then against the dancer's other takes
AGAINST_TAKE = ("movement_min", "movement_max", "jitter", "speed", "coverage", "global_diversity")
AGAINST_TAKE += ("local_diversity", "inter_diversity")
COLUMNS = (*AGAINST_TAKE, "fid_g_other")


def figures(run: Path) -> dict:
  one = json.loads((run / "one_take.json").read_text())
  out = {k: mean(one[k]) for k in AGAINST_TAKE if k in one}
  if (run / "other_takes.json").exists():
    o = json.loads((run / "other_takes.json").read_text())
    out["fid_g_other"] = mean(o["fid_g"]) / mean(o["fid_g_train"])
  return out


RESULTS = Path(__file__).resolve().parent / "results.json"


def record(runs: list[Path]) -> dict:
  """The figures of every evaluated run in ``runs`` merged into results.json (by run name)."""
  results = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
  results |= {run.name: figures(run) for run in runs if (run / "one_take.json").exists()}
  RESULTS.write_text(json.dumps(results, indent=1, sort_keys=True) + "\n")
  return results


def table(results: dict) -> str:
  """Mean [least, most] over a recipe's seeds on each take."""
  groups: dict = {}
  for name, f in results.items():
    groups.setdefault(re.sub(r"-seed=\d+$", "", name), []).append(f)
  head = "| runs | n | " + " | ".join(COLUMNS) + " |"
  lines = [head, "|" + "---|" * (2 + len(COLUMNS))]
  for name, rows in sorted(groups.items()):
    cells = []
    for k in COLUMNS:
      v = [r[k] for r in rows if k in r]
      cells.append("-" if not v else f"{np.mean(v):.2f}" + (f" [{min(v):.2f}, {max(v):.2f}]" if len(v) > 1 else ""))
    lines.append(f"| {name} | {len(rows)} | " + " | ".join(cells) + " |")
  return "\n".join(lines)


if __name__ == "__main__":
  p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  p.add_argument("runs", nargs="*", type=Path)
  p.add_argument("--patch", action="store_true")
  p.add_argument("--table", action="store_true")
  a = p.parse_args()
  if a.patch:
    for take in sorted(TAKES.iterdir()):
      evaluate(patch(take))
  for run in a.runs:
    evaluate(run)
  results = record(sorted((ROOT / "runs" / "one_take").glob("*-*")))
  if a.table:
    print(table(results))
