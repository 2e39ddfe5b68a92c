"""The table of experiments/library/README.md from the judge's results (``results/RECIPE-seed=N.json``).

python experiments/library/table.py
"""

from __future__ import annotations

import json
import re
from collections import defaultdict
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent


def _each(values, fmt="{:.2f}") -> str:
  return ", ".join(fmt.format(v) for v in values)


def _row(recipe: str, runs: list[dict]) -> str:
  ratio = lambda f: _each([r["fields"][f]["ratio"] for r in runs])
  inside = lambda k: _each([np.mean([0.7 <= p[k] <= 1.3 for p in r["per_pair"]]) for r in runs], "{:.0%}")
  median = lambda k: _each([np.median([p[k] for p in r["per_pair"]]) for r in runs])
  fid = lambda k: (
    _each([r["pooled"][k]["mean"] for r in runs], "{:.1f}") + f" ({runs[0]['pooled'][k + '_real']['mean']:.1f})"
  )
  seeds = ", ".join(str(r["run"].rsplit("=", 1)[-1]) for r in runs)
  cells = [
    recipe,
    seeds,
    ratio("action"),
    ratio("style"),
    inside("movement"),
    inside("jitter"),
    median("movement") + " / " + median("jitter"),
    fid("fid_k"),
    fid("fid_g"),
  ]
  return "| " + " | ".join(cells) + " |"


def main() -> None:
  by_recipe: dict[str, list[dict]] = defaultdict(list)
  for f in sorted((HERE / "results").glob("*-seed=*.json")):
    recipe = re.sub(r"-seed=\d+$", "", f.stem)
    by_recipe[recipe] += json.loads(f.read_text())
  print(
    "| recipe | seeds | action: samples / held-out | style: samples / held-out "
    "| pairs with movement in 0.7-1.3 | with jitter in 0.7-1.3 | movement / jitter, median pair "
    "| FID_k (real's own) | FID_g (real's own) |"
  )
  print("|---|---|---|---|---|---|---|---|---|")
  for recipe, runs in by_recipe.items():
    print(_row(recipe, runs))


if __name__ == "__main__":
  main()
