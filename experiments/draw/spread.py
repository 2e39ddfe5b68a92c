"""The quickstart against the white recipe's spread on the two smallest dancers (CMU 5, CMU 131), six training
seeds each: every figure of the dancers benchmark, mean +- std over the seeds and [the least, the most], and
whether the quickstart's is no worse than the white recipe's spread.

  python experiments/draw/spread.py             # the README's table ("Against the white recipe's spread")
  python experiments/draw/spread.py --record RUN NAME   # a quickstart run's own eval into results.json

The white recipe's runs are read from their kept small files (`experiments/dancers/results/`: `dancers_obj`,
seeds 0-2, trained on an H100; `dancers_more`, seeds 3-5, trained on 2 CPU cores by `experiments/dancers/
sweep.toml`'s cmu05 and cmu131 at those seeds); the quickstart's from `results.json` (the "shipped" draw of the
rows named below). A figure is no worse when the quickstart's mean is as near the held-out take as the white
recipe's (ratios: nearer 1; FID: lower), or within the white recipe's mean +- std.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from ablate import RESULTS, figures, record  # noqa: E402

WHITE = HERE.parent / "dancers" / "results"
WHITE_RUNS = {
  d: [*(WHITE / "dancers_obj").glob(f"obj-{d}-seed=*"), *(WHITE / "dancers_more").glob(f"white-{d}-seed=*")]
  for d in ("cmu05", "cmu131")
}
# the quickstart's rows in results.json (CMU 5's seeds 0-2: the rows "the lift paced"; the others recorded from
# `carried_more.toml`'s runs, seeds 3-5, by --record)
QUICKSTART = {
  "cmu05": (
    "cmu05 memory 3, smooth carry, acceleration axes, 4,000 steps, last checkpoint, the lift paced, seed ",
    "cmu05 quickstart, seed ",
  ),
  # seeds 0-2: trained as data.augment = [], the data the quickstart trains CMU 131 on (test_dataset)
  "cmu131": ("cmu131 quickstart without mirrored copies, seed ", "cmu131 quickstart, seed "),
}
FAR = lambda v: abs(np.log(v))  # a ratio's distance from the held-out take's own (1)
FIGURES = {  # column -> (title, the dancers benchmark's bar or None, how far from the held-out take)
  "movement_min": ("calmest 1,000", (0.7, 1.3), FAR),
  "movement_max": ("busiest 1,000", (0.7, 1.3), FAR),
  "jitter": ("jitter", (0.7, 1.3), FAR),
  "speed": ("speed", (0.8, 1.25), FAR),
  "root_travel": ("root travel", (0.8, 1.25), FAR),
  "root_step_max": ("largest root step", (0.0, 1.5), lambda v: max(np.log(v), 0.0)),  # a bar above only
  "fid_k": ("FID_k / train", None, lambda v: v),
  "fid_g": ("FID_g / train", None, lambda v: v),
}


def white(dancer: str) -> list[dict]:
  return [figures(json.loads((r / "eval" / "metrics.json").read_text())) for r in sorted(WHITE_RUNS[dancer])]


def quickstart(dancer: str) -> list[dict]:
  results = json.loads(RESULTS.read_text())
  return [v["shipped"] for k, v in results.items() if k.startswith(QUICKSTART[dancer]) and "shipped" in v]


def cell(values) -> str:
  v = np.asarray(values)
  return f"{v.mean():.2f} +- {v.std(ddof=1):.2f} [{v.min():.2f}, {v.max():.2f}]"


def verdict(ours, theirs, bar, far) -> str:
  """Whether the quickstart's seeds (``ours``) are no worse than the white recipe's (``theirs``) on a figure:
  every seed within the benchmark's ``bar``; else its mean as near the held-out take as theirs, or within
  their mean +- std."""
  a, b = np.mean(ours), np.mean(theirs)
  if bar and all(bar[0] <= v <= bar[1] for v in ours):
    return "yes: every seed within the bar"
  if far(a) <= far(b):
    return "yes: nearer"
  if abs(a - b) <= np.std(theirs, ddof=1):
    return "yes: within the spread"
  return "**no**"


def table() -> list[str]:
  out = ["| dancer | figure | white | quickstart | no worse |", "|---|---|---|---|---|"]
  for dancer in QUICKSTART:
    w, q = white(dancer), quickstart(dancer)
    out[0] = f"| dancer | figure | white ({len(w)} seeds) | quickstart ({len(q)} seeds) | no worse |"
    for key, (title, bar, far) in FIGURES.items():
      a, b = [r[key] for r in q], [r[key] for r in w]
      out.append(f"| {dancer} | {title} | {cell(b)} | {cell(a)} | {verdict(a, b, bar, far)} |")
  return out


if __name__ == "__main__":
  if sys.argv[1:2] == ["--record"]:
    run, name = Path(sys.argv[2]), sys.argv[3]
    record(name, "shipped", figures(json.loads((run / "eval" / "metrics.json").read_text())))
  else:
    print("\n".join(table()))
