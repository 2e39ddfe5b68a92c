"""The in-betweening systems on their own training takes beside the held-out ones: how much of what a
model does better than linear interpolation carries over to motion it has not seen.

Position error over linear interpolation's, transitions of 5, 15 and 30 frames in windows every 40 frames
(the protocol of evaluate.py), on cmu94's nine training takes (as read, no mirror or reverse) and on
each held-out set. Several seeds of one config make one row (mean +- sd). Run from the repository root
after training (about a minute for six runs on 2 cores):

  .venv/bin/python experiments/inbetween/gap.py runs/inbetween/*

Prints a markdown table (README.md, "Seen and unseen motion").
"""

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from evaluate import BASELINES, cell, groups_of, held_out, methods_of

from benchmarks import lafan1
from chorjax.data.dataset import load_dataset
from chorjax.families.inbetween import inbetweening as ib
from chorjax.run import load_run

LENGTHS = (5, 15, 30)


def main() -> None:
  parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
  parser.add_argument("runs", nargs="+", help="trained in-betweening run directories")
  args = parser.parse_args()
  runs = [load_run(w) for w in args.runs]
  first = runs[0]
  context, space = first.config.inbetween.context, ib.Space.of(first.features)
  ds = load_dataset(first.config.data)
  train = ib.training_takes(ds, ())
  std, feet = lafan1.window_std(train, space, context), first.features.skeleton.feet
  methods = methods_of(runs)
  sets = {f"cmu94 training takes ({len(train)})": train, **held_out(first)}
  print("| system | takes | " + " | ".join(f"{n} frames" for n in LENGTHS) + " |")
  print("|---|---|" + "---|" * len(LENGTHS))
  results = {
    name: lafan1.benchmark(methods, takes, space, feet, context, std, lengths=LENGTHS) for name, takes in sets.items()
  }
  for group, members in groups_of(runs).items():
    if group in BASELINES:
      continue
    for name, r in results.items():
      cells = [cell(r, members, n, "position_error", 2, over_linear=True) for n in LENGTHS]
      print(f"| {group} | {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
  main()
