"""The filmstrips of ``README.md``: the last 900 frames of a run's 10,000-frame draw (its own, ``chorjax sample RUN
--plain``, or an eval's ``sample.npz``, titled TITLE) beside a held-out take of its dancer.

  python experiments/draw/strips.py NAME SAMPLE.npz [TITLE]   # writes experiments/draw/strip_NAME.png
  python experiments/draw/strips.py --real DATASET RUN    # writes experiments/draw/strip_DATASET_real.png
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _results import end_strip, real_strip

HERE = Path(__file__).resolve().parent

if __name__ == "__main__":
  if sys.argv[1] == "--real":
    real_strip(Path(sys.argv[3]), HERE / f"strip_{sys.argv[2]}_real.png", sys.argv[2])
  else:
    name, sample = sys.argv[1], Path(sys.argv[2])
    end_strip(sample, HERE / f"strip_{name}.png", sys.argv[3] if len(sys.argv) > 3 else f"{name}, own draw")
