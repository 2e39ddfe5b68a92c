"""Writes the Bandai dance as two takes (the first 80% to train on, the last 20% held out) into
runs/other_dancers/data/bandai/: CSVs on the take's own 22-joint skeleton with their .skeleton.json
sidecars. The Bandai Namco data is CC BY-NC 4.0: it is read from ../shared/data and never committed.

  .venv/bin/python experiments/other_dancers/prepare.py
"""

from pathlib import Path

from chorjax.data.bvh import read_bvh
from chorjax.data.csv import write_csv

SOURCE = Path("../shared/data/bvh/bandai/dataset-1_dance-short_normal_001.bvh")
OUT = Path("runs/other_dancers/data/bandai")

if __name__ == "__main__":
  take = read_bvh(SOURCE)
  cut = int(0.8 * take.num_frames)
  for name, rows in (("dance_1", slice(0, cut)), ("dance_2", slice(cut, None))):
    part = take.replace(positions=take.positions[rows], name=name)
    print(f"wrote {write_csv(part, OUT / f'{name}.csv')} ({part.num_frames} frames)")
