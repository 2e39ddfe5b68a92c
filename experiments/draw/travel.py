"""Where a run's root travel goes: its draw's root path per frame, across the floor and up and down, and the root
height's spread, each over the run's training takes' own; and the training takes' over the held-out takes'.
Beside them, which side the dancer favours: the right foot's mean speed over the left's, drawn and in the
training takes (a dancer and its mirror image are told apart by it).

A run's draw is calibrated on its training takes, so it travels about as they do; the dancers benchmark judges
it against the held-out takes. The two ratios printed side by side say which of the two a shortfall comes from.

  python experiments/draw/travel.py RUN [RUN ...] [--frames 10000] [--seed 0]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

COLUMNS = ("across", "up/down", "path", "height 5-95%", "height spread in 1 s")


def figures(takes, root: int) -> np.ndarray:
  """Per frame: the root's mean step across the floor, up and down, and in all; the root height's 5-95% range
  and its standard deviation within 1-second windows (30 frames, half overlapping)."""
  steps = np.concatenate([np.diff(p[:, root], axis=0) for p in takes])
  height = np.concatenate([p[:, root, 1] for p in takes])
  spread = np.concatenate([[p[i : i + 30, root, 1].std() for i in range(0, len(p) - 30, 15)] for p in takes])
  return np.array(
    [
      np.linalg.norm(steps[:, [0, 2]], axis=-1).mean(),
      np.abs(steps[:, 1]).mean(),
      np.linalg.norm(steps, axis=-1).mean(),
      np.percentile(height, 95) - np.percentile(height, 5),
      spread.mean(),
    ]
  )


def sides(takes, skeleton) -> float:
  """The right foot's mean speed per frame over the left foot's (the skeleton's first foot and its twin)."""
  right, left = skeleton.feet[0], skeleton.twins[skeleton.feet[0]]
  speed = np.concatenate([np.linalg.norm(np.diff(p, axis=0), axis=-1) for p in takes])
  return float(speed[:, right].mean() / speed[:, left].mean())


def measure(run_dir: Path, frames: int, seed: int) -> tuple[np.ndarray, np.ndarray, tuple[float, float]]:
  """(the draw's figures / the training takes', the training takes' / the held-out takes', the right foot's speed
  over the left's (the draw's, the training takes'))."""
  from chorjax.data.transforms import to_y_up
  from chorjax.run import HELD_OUT, load_run, read_reference

  run = load_run(run_dir)
  y_up = lambda p: np.asarray(to_y_up(p, run.features.up_axis))
  real, train = read_reference(run, [HELD_OUT])
  with tempfile.TemporaryDirectory() as tmp:
    out = Path(tmp) / "draw.npz"
    cmd = [str(Path(sys.executable).parent / "chorjax"), "sample", str(run_dir), "-o", str(out)]
    subprocess.run([*cmd, "--frames", str(frames), "--seed", str(seed)], check=True, stdout=subprocess.DEVNULL)
    drawn = y_up(np.load(out)["positions"][0])
  skeleton = run.features.skeleton
  taken = [y_up(m.positions) for m in train]
  trained = figures(taken, skeleton.root)
  held = figures([y_up(m.positions) for m in real], skeleton.root)
  return figures([drawn], skeleton.root) / trained, trained / held, (sides([drawn], skeleton), sides(taken, skeleton))


def main() -> None:
  p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  p.add_argument("runs", nargs="+", type=Path)
  p.add_argument("--frames", type=int, default=10_000)
  p.add_argument("--seed", type=int, default=0, help="sampling seed (the run's calibrated draw)")
  args = p.parse_args()
  head = [f"draw / training: {c}" for c in COLUMNS] + ["training / held-out: path", "right / left foot: draw, training"]
  print("| run | " + " | ".join(head) + " |")
  print("|---|" + "---|" * len(head))
  for run in args.runs:
    drawn, trained, (side, side_trained) = measure(run, args.frames, args.seed)
    cells = [f"{v:.2f}" for v in drawn] + [f"{trained[2]:.2f}", f"{side:.2f}, {side_trained:.2f}"]
    print(f"| {run.name} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
  main()
