"""The dancers benchmark's "learned" columns: each trained benchmark run, kept at its best validation
checkpoint (train.keep = "best") and calibrated on its own training takes (chorjax calibrate, as it is
today), judged like the baseline (held-out takes, 4 sampling seeds x 10,000 frames). The runs are copied:
the runs they come from stay as they were. Skips finished copies, so it can run beside a sweep and again.

  .venv/bin/python experiments/dancers/learned.py                # runs/dancers -> runs/dancers_learned
  .venv/bin/python experiments/dancers/learned.py runs/dancers_best runs/dancers_cal5 cal5-
  .venv/bin/python experiments/dancers/learned.py runs/dancers_pca runs/dancers_ground ground- sample.ground=true
  chorjax compare runs/dancers_learned/learned-* -o experiments/dancers/learned_report.md
  # calibration's walk past the grid's ends (2026-11-26): each run's own measured settings not drawn again
  .venv/bin/python experiments/dancers/learned.py runs/dancers_poses runs/dancers_beyond beyond- --reuse
  # calibration on longer draws (2026-11-26, session 23; SRC: links to the LSTM quickstart's runs)
  .venv/bin/python experiments/dancers/learned.py SRC runs/dancers_long long- --frames 2400 --num 2
"""

import json
import shutil
import subprocess
import sys
from pathlib import Path

CHORJAX = str(Path(sys.executable).with_name("chorjax"))


def main(
  base: Path = Path("runs/dancers"),
  out: Path = Path("runs/dancers_learned"),
  prefix: str = "learned-",
  sets=(),
  reuse: bool = False,
  calibrate_args=(),
) -> None:
  """Copies of ``base``'s evaluated runs in ``out``, named ``prefix`` + the point, with ``sets`` (``SECTION.KEY=
  true|false|number``) changed in their config, calibrated and evaluated. ``reuse``: the settings the run's
  own calibration.json measured are not drawn again (the same checkpoint and draws), and where the choice
  is the same its evaluation is kept (the same checkpoint, settings and sampling seeds: the same dance).
  ``calibrate_args``: flags for `chorjax calibrate` (``--frames N``, ``--num N``). A copy whose checkpoint and
  chosen settings are its run's keeps the run's evaluation."""
  from chorjax.sampling.calibrate import MEASURES, calibrate

  if reuse and (sets or calibrate_args):
    raise SystemExit("--reuse draws what the runs drew: it changes nothing in their config or draws")
  out.mkdir(parents=True, exist_ok=True)
  for run in sorted(base.glob("*-seed=*")):
    if not (run / "eval" / "metrics.json").exists():
      continue  # not trained and evaluated yet
    copy = out / (prefix + run.name.split("-", 1)[1])
    if (copy / "eval" / "metrics.json").exists():
      continue
    shutil.rmtree(copy, ignore_errors=True)
    shutil.copytree(run, copy, ignore=shutil.ignore_patterns("eval", "events.*", "calibration.json"))
    config = json.loads((copy / "config.json").read_text())
    trained = dict(config["train"])  # the run's own, before any change
    if not reuse:  # reuse keeps the checkpoint the measured table was drawn from
      config["train"].update(keep="best", calibrate=True)
    for assignment in sets:
      key, value = assignment.split("=", 1)
      section, name = key.split(".")
      config[section][name] = json.loads(value)
    config["name"] = copy.name
    (copy / "config.json").write_text(json.dumps(config, indent=2))
    before = json.loads((run / "calibration.json").read_text()) if (run / "calibration.json").exists() else {}
    if reuse:
      known = [(r["settings"], {k: r[k] for k in MEASURES}) for r in before["table"]]
      calibrate(copy, known=known, log=lambda line: None)
    else:
      subprocess.run([CHORJAX, "calibrate", str(copy), *calibrate_args], check=True)
    same_run = reuse or (not sets and config["train"] == trained)
    if same_run and json.loads((copy / "calibration.json").read_text())["settings"] == before.get("settings"):
      shutil.copytree(run / "eval", copy / "eval")  # the same checkpoint, settings and sampling seeds
      continue
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
  args, flags = [a for a in sys.argv[1:] if a != "--reuse"], []
  for flag in ("--frames", "--num"):
    if flag in args:
      i = args.index(flag)
      flags += args[i : i + 2]
      del args[i : i + 2]
  main(*(Path(a) for a in args[0:2]), *args[2:3], sets=args[3:], reuse="--reuse" in sys.argv, calibrate_args=flags)
