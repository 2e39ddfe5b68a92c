"""The families within their training length: every trained point of the families sweep sampled 8 times
for 64 frames (the length of one training window) and scored with 30-frame windows, then the table of
mean +- sd over the training seeds written to experiments/families/short_report.md. Run from the
repository root after the sweep:

  .venv/bin/python experiments/families/short.py
"""

import json
import re
from pathlib import Path

import numpy as np

from chorjax.evaluation.evaluate import evaluate
from chorjax.evaluation.scoring import mean_of

ROOT = Path("runs/families")
OUT = Path("experiments/families/short_report.md")
KEYS = [
  ("movement_first", "movement"),
  ("jitter", "jitter"),
  ("fid_k", "FID_k / real"),
  ("fid_g", "FID_g / real"),
  ("div_k", "Div_k"),
  ("novelty", "novelty"),
]


def score(workdir: Path) -> dict:
  path = workdir / "eval" / "short.json"
  if not path.exists():
    result = evaluate(workdir, ["cmu94"], frames=64, num=8, seeds=[0, 1], window=30, splits=10)
    result.pop("first_sample")
    path.write_text(json.dumps(result, indent=2))
  return json.loads(path.read_text())


def cell(results, key) -> str:
  real = key in ("fid_k", "fid_g")
  values = [mean_of(r[key]) / (mean_of(r[key + "_real"]) if real else 1.0) for r in results]
  return f"{np.mean(values):.3g} ± {np.std(values, ddof=1):.2g}" if len(values) > 1 else f"{values[0]:.3g}"


if __name__ == "__main__":
  groups: dict[str, list] = {}
  for w in sorted(ROOT.glob("families-*-seed=*")):
    if (w / "eval" / "metrics.json").exists():
      groups.setdefault(re.sub(r"-seed=\d+", "", w.name), []).append(score(w))
  lines = [
    "| family | seeds | " + " | ".join(label for _, label in KEYS) + " |",
    "|---" * (2 + len(KEYS)) + "|",
  ]
  for name, results in groups.items():
    lines.append(f"| {name} | {len(results)} | " + " | ".join(cell(results, k) for k, _ in KEYS) + " |")
  r0 = next(iter(groups.values()))[0]
  real = lambda k: f"{mean_of(r0[k]):.3g}"
  lines.append(
    f"| real data | | 1 | 1 | 1 ({real('fid_k_real')}) | 1 ({real('fid_g_real')}) | {real('div_k_real')} | "
    f"{real('novelty_real')} |"
  )
  OUT.write_text(
    "Within the training length: 8 dancers x 64 frames per sampling seed (0, 1) per trained model, scored against "
    "all ten cmu94 takes with 30-frame windows; cells are mean ± sd over the three training seeds "
    "(`experiments/families/short.py`).\n\n" + "\n".join(lines) + "\n"
  )
  print(OUT.read_text())
