"""BENCHMARKS.md's opening table, written from the results files: one figure per cell, with its machine.

    python -m benchmarks.opening     # rewrites the table in BENCHMARKS.md (benchmarks.run does it too)

Its rows come from ``results_shipped.json`` (``benchmarks.shipped``: the shipped configuration's CPU train step
against PyTorch), ``results_gpu.json`` (``benchmarks.gpu``), ``results_wall.json`` (``benchmarks.wall``: the
README's commands in a fresh clone, a sample) and ``results.json`` (``benchmarks.run``: the peak memory of
training). A test checks that the table in BENCHMARKS.md is the one these files make.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

HERE = Path(__file__).resolve().parent
BENCHMARKS = HERE.parent / "BENCHMARKS.md"
START = "<!-- the opening table: python -m benchmarks.opening writes it from benchmarks/results*.json -->"
END = "<!-- end of the opening table -->"


def _read(name: str) -> dict:
  return json.loads((HERE / name).read_text())


def _cpu(description: str) -> str:
  """``"AMD EPYC, 2 cores, cpu; Python ..."`` -> ``"2 CPU cores (AMD EPYC)"``."""
  found = re.match(r"(.*?), (\d+) cores", description)
  return f"{found.group(2)} CPU cores ({found.group(1)})" if found else description.split(";")[0]


def _ms(seconds: float) -> str:
  return f"{seconds * 1e3:.3g} ms" if seconds < 0.01 else f"{seconds * 1e3:.1f} ms"


def rows() -> list[tuple[str, str, str, str, str]]:
  """(measure, chorjax, PyTorch, ratio, where) for each row."""
  out = []
  shipped = _read("results_shipped.json")
  where = _cpu(shipped["machine"])
  for head in ("mdn", "mse"):
    r = shipped[f"lstm {head} shipped"]
    out.append((f"train step, {head.upper()} head", _ms(r["chorjax"]), _ms(r["torch"]), f"{r['ratio']:.2f}x", where))
  gpu = _read("results_gpu.json")
  device = f"one {gpu['info']['device']}"
  step, peer = gpu["chorjax lstm shipped"], gpu["torch lstm shipped"]
  out.append(("train step, MDN head", _ms(step), _ms(peer), f"{peer / step:.2f}x", device))
  drawn, peer = gpu["chorjax sample smoothed b1"], gpu["torch sample b1"]
  measure = "sampling 1,000 frames, batch 1 (configs/white.toml's smoothed draw)"
  out.append((measure, f"{drawn:.3f} s", f"{peer:.3f} s", f"{peer / drawn:.0f}x", device))
  wall = _read("results_wall.json")
  said = {
    "quickstart": "the quick start (README command 1: install with its extras from pip's cache, train, calibrate, "
    "sample) in a fresh clone",
    "suite": "the test suite (`.ci/run`: its installs, ruff, pyright and `pytest -q`, {tests} tests) in a fresh clone",
    "sample": "`chorjax sample` of the quick start's run (600 frames), the first time and after (compiled programs "
    "kept)",
  }
  for name, text in said.items():
    w = wall[name]
    out.append((f"{text.format(**w)}, {w['date']}", w["figure"], "", "", w["machine"]))
  run = _read("results.json")
  peak = run["peak_rss_mb_default_training"] / 1024  # MiB of VmHWM
  measure = "peak resident memory, 20 training steps with a checkpoint and the end sample"
  out.append((measure, f"{peak:.2f} GiB", "", "", _cpu(run["machine"]["description"])))
  return out


def table() -> str:
  lines = ["| measure | chorjax | PyTorch | ratio | where |", "|---|---|---|---|---|"]
  lines += ["| " + " | ".join(r) + " |" for r in rows()]
  return "\n".join([START, *lines, END])


def write(path: Path = BENCHMARKS) -> None:
  """Replaces the opening table of ``path`` (between its markers) with :func:`table`."""
  text = path.read_text()
  before, rest = text.split(START, 1)
  after = rest.split(END, 1)[1]
  path.write_text(before + table() + after)
  print(f"wrote the opening table of {path}")


if __name__ == "__main__":
  write()
