"""Which takes to hold out: every pair of a dataset's takes, its remaining takes scored as a sample against
the pair (what real dance by this dancer scores on the benchmark's bars), nearest first.

  .venv/bin/python experiments/dancers/split.py                        # cmu94, the bundled dancer
  .venv/bin/python experiments/dancers/split.py data.dataset=../shared/data/aclstm/martial data.resample_fps=30

A held-out pair is a fair judge when the dancer's own training takes pass issue 35's bars against it (every
1,000-frame segment's movement 0.7-1.3, jitter 0.7-1.3, speed and root travel 0.8-1.25, largest root step
<= 1.5x): real dance by this dancer must pass what a model of it is held to. Pairs that do come first,
nearest first; "nearest" is the largest |log| of speed, root travel and jitter. Reads the takes as
`chorjax train configs/quickstart.toml KEY=VALUE...` would.
Pairs of single takes only (salsa's partners, which must stay together, are not paired here).
"""

import itertools
import sys

import numpy as np

from chorjax.config import load_config
from chorjax.data.dataset import conform, load_dataset, read_takes
from chorjax.data.transforms import to_y_up
from chorjax.evaluation.scoring import mean_of, score

BARS = ("jitter", "speed", "root_travel")


def passes(m: dict) -> bool:
  """Whether measures of real takes pass issue 35's bars."""
  return (
    m["calmest"] >= 0.7
    and m["busiest"] <= 1.3
    and 0.7 <= m["jitter"] <= 1.3
    and all(0.8 <= m[k] <= 1.25 for k in ("speed", "root_travel"))
    and m["root_step_max"] <= 1.5
  )


def pair_scores(overrides: list[str]) -> list[tuple[float, tuple[str, str], dict]]:
  """``(nearness, pair, measures)`` for every pair of takes: those that pass the bars first, nearest first."""
  data = load_config("configs/quickstart.toml", overrides).data
  ds = load_dataset(data)
  every = conform(read_takes([data.dataset], data), data)
  takes = {m.name: np.asarray(to_y_up(m.positions, ds.features.up_axis)) for m in every}
  rows = []
  for pair in itertools.combinations(sorted(takes), 2):
    held = [takes[n] for n in pair]
    train = [p for n, p in takes.items() if n not in pair]
    e = score(train, held, ds.features.skeleton, ds.fps, train=train, unseen=held)
    m = {k: mean_of(e[k]) for k in (*BARS, "root_step_max")}
    m["calmest"], m["busiest"] = e["movement_min_train"], e["movement_max_train"]
    rows.append((max(abs(np.log(m[k])) for k in BARS), pair, m))
  return sorted(rows, key=lambda r: (not passes(r[2]), r[0]))


def main() -> None:
  head = ("held out", "passes", "|log| farthest", "speed", "root travel", "jitter", "calmest / busiest", "root step")
  print("| " + " | ".join(head) + " |\n" + "|---" * len(head) + "|")
  for near, pair, m in pair_scores(sys.argv[1:]):
    cells = [f"{m[k]:.2f}" for k in ("speed", "root_travel", "jitter")]
    seg = f"{m['calmest']:.2f} / {m['busiest']:.2f}"
    row = [", ".join(pair), "yes" if passes(m) else "no", f"{near:.2f}", *cells, seg, f"{m['root_step_max']:.2f}"]
    print("| " + " | ".join(row) + " |")


if __name__ == "__main__":
  main()
