"""The dancers benchmark's "learned" column: each trained benchmark run, kept at its best validation
checkpoint (train.keep = "best") and calibrated on its own training takes (chorjax calibrate), judged
like the baseline (held-out takes, 4 sampling seeds x 10,000 frames). The runs are copied: the baseline
runs stay as trained. Skips finished copies, so it can run beside the sweep and again after it.

  .venv/bin/python experiments/dancers/learned.py
  chorjax compare runs/dancers_learned/learned-* -o experiments/dancers/learned_report.md
"""

import json
import shutil
import subprocess
import sys
from pathlib import Path

BASE, OUT = Path("runs/dancers"), Path("runs/dancers_learned")
CHORJAX = str(Path(sys.executable).with_name("chorjax"))


def main() -> None:
  OUT.mkdir(parents=True, exist_ok=True)
  for run in sorted(BASE.glob("dancers-*")):
    if not (run / "eval" / "metrics.json").exists():
      continue  # not trained and evaluated yet
    copy = OUT / run.name.replace("dancers-", "learned-", 1)
    if (copy / "eval" / "metrics.json").exists():
      continue
    shutil.rmtree(copy, ignore_errors=True)
    shutil.copytree(run, copy, ignore=shutil.ignore_patterns("eval", "events.*"))
    config = json.loads((copy / "config.json").read_text())
    config["train"].update(keep="best", calibrate=True)
    config["name"] = copy.name
    (copy / "config.json").write_text(json.dumps(config, indent=2))
    subprocess.run([CHORJAX, "calibrate", str(copy)], check=True)
    subprocess.run(
      [
        CHORJAX,
        "eval",
        str(copy),
        "--data",
        "held-out",
        "--frames",
        "10000",
        "--num",
        "1",
        "--seeds",
        "0",
        "1",
        "2",
        "3",
      ],
      check=True,
    )


if __name__ == "__main__":
  main()
