"""What a user waits for, on this machine: the README's two commands in a fresh clone, and a sample.

    python -m benchmarks.wall --quickstart   # README command 1 in a fresh clone (install, train, calibrate, sample)
    python -m benchmarks.wall --suite        # README command 2 as CI runs it (.ci/run) in a fresh clone
    python -m benchmarks.wall --sample RUN   # chorjax sample of RUN (600 frames), the first time and again

Each measure replaces its entry in ``benchmarks/results_wall.json`` (the figure, the date and the machine), from
which ``python -m benchmarks.opening`` writes BENCHMARKS.md's opening table. A fresh clone is ``git clone`` of
this checkout's HEAD into a temporary folder with ``../shared`` beside it, as CI has it; pip reads from its cache.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
OUT = HERE / "results_wall.json"


def machine() -> str:
  """This machine in words: core count and CPU model (family and model: VMs of one name differ)."""
  from chorjax.runtime import cpu_info

  info = cpu_info()
  name = re.sub(r"\s+\d+-Core Processor$", "", info.get("model name", "CPU"))
  return f"{os.cpu_count()} CPU cores ({name} family {info.get('cpu family', '?')}, model {info.get('model', '?')})"


def _fresh_clone(tmp: Path) -> Path:
  (tmp / "shared").symlink_to((ROOT.parent / "shared").resolve())
  subprocess.run(["git", "clone", "-q", str(ROOT), str(tmp / "main")], check=True)
  return tmp / "main"


def _readme_command(n: int) -> str:
  """The README quick start's ``n``-th command (1: install and train, 2: install and test)."""
  section = (ROOT / "README.md").read_text().split("## Quick start", 1)[1].split("\n## ", 1)[0]
  return re.findall(r"```bash\n(.*?)\n```", section, re.S)[n - 1].strip()


def _timed(command: str, cwd: Path) -> float:
  start = time.monotonic()
  subprocess.run(["bash", "-c", command], cwd=cwd, check=True, stdout=subprocess.DEVNULL)
  return time.monotonic() - start


def _minutes(seconds: float) -> str:
  return f"{int(seconds // 60)} min {round(seconds % 60):d} s"


def quickstart() -> dict:
  with tempfile.TemporaryDirectory() as tmp:
    s = _timed(_readme_command(1), _fresh_clone(Path(tmp)))
  return {"figure": _minutes(s), "seconds": s}


def suite() -> dict:
  with tempfile.TemporaryDirectory() as tmp:
    clone = _fresh_clone(Path(tmp))
    start = time.monotonic()
    env = {**os.environ, "CI": "true"}
    done = subprocess.run(["bash", ".ci/run"], cwd=clone, env=env, capture_output=True, text=True)
    s = time.monotonic() - start
  if done.returncode:
    sys.exit(f".ci/run failed:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}")
  tests = re.findall(r"(\d+) passed in ([\d.]+)s", done.stdout)
  passed, pytest_s = (int(tests[-1][0]), float(tests[-1][1])) if tests else (0, 0.0)
  return {"figure": f"{_minutes(s)} (pytest {_minutes(pytest_s)})", "seconds": s, "tests": passed}


def sample(run: str) -> dict:
  with tempfile.TemporaryDirectory() as tmp:
    cmd = f"{sys.executable} -m chorjax.cli sample {run} -o {tmp}/s.csv --frames 600 --force"
    first, again = _timed(cmd, ROOT), _timed(cmd, ROOT)
  return {"figure": f"{first:.1f} s, then {again:.1f} s", "seconds": [first, again]}


def record(name: str, result: dict) -> None:
  results = json.loads(OUT.read_text()) if OUT.exists() else {}
  results[name] = {**result, "date": datetime.date.today().isoformat(), "machine": machine()}
  OUT.write_text(json.dumps(results, indent=1) + "\n")
  print(f"{name}: {result['figure']}; wrote {OUT}")


def main(argv=None) -> None:
  p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  p.add_argument("--quickstart", action="store_true", help="README command 1 in a fresh clone")
  p.add_argument("--suite", action="store_true", help=".ci/run in a fresh clone")
  p.add_argument("--sample", metavar="RUN", help="chorjax sample of RUN, 600 frames, twice")
  args = p.parse_args(argv)
  if args.quickstart:
    record("quickstart", quickstart())
  if args.suite:
    record("suite", suite())
  if args.sample:
    record("sample", sample(args.sample))


if __name__ == "__main__":
  main()
