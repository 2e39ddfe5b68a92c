"""Packs what a device call brings back (experiments/dancers/gpu/run.sh): OUT/small.tgz (every run's config,
calibration, metrics log and evaluation, and the logs in /tmp/gl) and, per sweep point, OUT/params-<point>.tgz (each
seed's best checkpoint step without its optimizer state, ~3 MB a run), as many as fit 60 MB (a device call brings
back at most 64 MB in 8 files): the first sweep's points first, then the fb-martial ones."""

import glob
import json
import sys
import tarfile
from pathlib import Path


def best_step(run: Path) -> Path | None:
  """The checkpoint step with the lowest validation loss orbax recorded beside it."""
  steps = []
  for step in (run / "checkpoints").glob("*"):
    metrics = step / "metrics" / "metrics"
    if metrics.exists():
      steps.append((json.loads(metrics.read_text())["val_loss"], step))
  return min(steps, key=lambda s: s[0])[1] if steps else None


def main(out: Path) -> None:
  small = ["runs/*/*/*.json", "runs/*/*/metrics.jsonl", "runs/*/*/eval/metrics.json"]
  with tarfile.open(out / "small.tgz", "w:gz") as t:
    for f in sorted(f for pattern in small for f in glob.glob(pattern)):
      t.add(f)
    t.add("/tmp/gl", arcname="logs")
  groups: dict[str, list[Path]] = {}
  for run in sorted(Path("runs").glob("*/*")):
    best = best_step(run)
    if best is not None:
      groups.setdefault(run.name.rsplit("-seed=", 1)[0], []).append(best)
  order = [k for k in groups if k.startswith("h100-")] + [k for k in groups if k.startswith("fb-martial")]
  total = 0
  for point in order:
    files = [f for b in groups[point] for f in b.rglob("*") if f.is_file() and "train" not in f.relative_to(b).parts]
    size = sum(f.stat().st_size for f in files)
    if total + size > 60e6:
      print("params left out:", point, size)
      continue
    total += size
    with tarfile.open(out / f"params-{point}.tgz", "w:gz") as t:
      for b in groups[point]:
        for item in b.iterdir():
          if item.name != "train":
            t.add(item)
    print("params", point, [b.name for b in groups[point]], size)


if __name__ == "__main__":
  main(Path(sys.argv[1]))
