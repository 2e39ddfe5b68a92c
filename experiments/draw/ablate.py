"""The draw's controls, each off in turn, and the model's own draw (``--plain``), on runs of the dancers
benchmark: every run given is evaluated on its held-out takes (``chorjax eval --data held-out``) once per
variant, and the figures that judge a dance go to ``results.json`` beside this file (merged with what is
there: a run and variant already measured is skipped).

  python experiments/draw/ablate.py RUN [RUN ...] [--variants plain shipped ...] [--frames 10000]
  python experiments/draw/ablate.py --table      # every run, as markdown
  python experiments/draw/ablate.py --summary    # over training seeds: mean [least, most]
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results.json"


def _keys(**controls) -> list[str]:
  """``--set sample.KEY=VALUE`` for each of the draw's opt-in controls."""
  return [a for k, v in controls.items() for a in ("--set", f"sample.{k}={json.dumps(v)}")]


# the opt-in controls (no flag of their own) as the model's own draw has them
OFF = {"pi_temperature": 1, "noise_smoothing": 0, "noise_order": 1, "persistence": 0, "crossfade": 0}
OFF |= {"scale_cap": 0, "clamp_steps": False}
OPT_INS_OFF = _keys(**OFF)
VARIANTS = {
  "shipped": [],
  "plain": ["--plain"],
  # the own draw, but always the most likely component: what switching components costs
  "plain, most likely component": [*_keys(**{**OFF, "pi_temperature": 0}), "--sigma-temperature", "1", "--pace", "0"]
  + ["--no-clamp"],
  # the own draw with every frame clipped to the training range (sample.clamp): what keeps it in bounds
  "plain, clamped": [*OPT_INS_OFF, "--sigma-temperature", "1", "--pace", "0", "--clamp"],
  # and held to the training takes' pace (sample.pace 2): the draw of at most three controls, measured
  "plain, clamped, paced": [*OPT_INS_OFF, "--sigma-temperature", "1", "--pace", "2", "--clamp"],
  "no noise filter": _keys(noise_smoothing=0, noise_order=1),
  "no pace governor": ["--pace", "0"],
  "no persistence, crossfade": _keys(persistence=0, crossfade=0),
  "no clamps, scale cap": ["--no-clamp", *_keys(clamp_steps=False, scale_cap=0)],
}
# ratios to the held-out takes' own figures, and FIDs over the training takes' own distance
COLUMNS = ("jitter", "speed", "root_travel", "movement_min", "movement_max", "fid_k", "fid_g", "root_step_max")


CALIBRATED_VARIANT = "calibrated temperature and feet, clamped"  # the draw of three controls, the run's own choice
# ... the mixture weights at full temperature, and the governor holding the pace (gain 2) while it is chosen and
# drawn: the three controls are the scale temperature, the clip and the governor
PACED_VARIANT = "calibrated temperature and feet, clamped, paced"
CALIBRATED_VARIANTS = {CALIBRATED_VARIANT: "plain, clamped", PACED_VARIANT: "plain, clamped, paced"}


def small_calibration(run_dir: Path, pace: float = 0.0) -> dict:
  """What ``chorjax calibrate`` chooses for a run that carries its noise (``calibrate.CARRIED_GRID``: the scale
  temperature and foot lock, on its training takes), the rest of the draw plain and clamped: run here, as the
  runs measured were trained with the quickstart's other ``[sample]`` keys; ``pace``: the governor's gain."""
  import jax

  from chorjax.data.transforms import to_y_up
  from chorjax.run import load_run, read_reference
  from chorjax.sampling.calibrate import CALIBRATION_DANCERS, CARRIED_BEYOND, CARRIED_GRID, search
  from chorjax.sampling.controls import PLAIN

  run = load_run(run_dir)
  reference, train = read_reference(run, None)
  up = run.features.up_axis
  motion, key, base = (
    run.dancer_conditions(train, CALIBRATION_DANCERS),
    jax.random.key(0),
    {**PLAIN, "clamp": True, "pace": pace},
  )
  ranged = run.ranged(run.sampling(**base))

  def draw(settings):
    s = run.sampling(**{**base, **settings})
    return np.asarray(
      to_y_up(run.family.dance(ranged.graphdef, ranged.params, ranged.features, motion, key, 1200, s), up)
    )

  takes = [np.asarray(to_y_up(m.positions, up)) for m in reference]
  best, _ = search(draw, takes, run.features.skeleton, run.fps, CARRIED_GRID, beyond=CARRIED_BEYOND)
  return best


def calibrated_flags(best: dict, variant: str) -> list[str]:
  """The plain, clamped (and paced) draw's flags with the chosen scale temperature and foot lock."""
  flags = list(VARIANTS[CALIBRATED_VARIANTS[variant]])
  flags[flags.index("--sigma-temperature") + 1] = str(best["sigma_temperature"])
  return [*flags, "--foot-lock" if best["foot_lock"] else "--no-foot-lock"]


def figures(metrics: dict) -> dict:
  mean = lambda k: metrics[k]["mean"] if isinstance(metrics[k], dict) else metrics[k]
  out = {k: mean(k) for k in COLUMNS}
  out["fid_k"] /= mean("fid_k_train")
  out["fid_g"] /= mean("fid_g_train")
  out["heldout_loss"] = metrics["heldout_loss"]
  out["airborne"] = mean("airborne")  # a fraction of the frames (the held-out takes': airborne_real)
  return out


def measure(run: Path, variant: str, frames: int, seeds: list[int]) -> dict:
  chosen = small_calibration(run, 2.0 if variant == PACED_VARIANT else 0.0) if variant in CALIBRATED_VARIANTS else None
  flags = calibrated_flags(chosen, variant) if chosen else VARIANTS[variant]
  with tempfile.TemporaryDirectory() as tmp:
    out = Path(tmp) / "metrics.json"
    cmd = [
      str(Path(sys.executable).parent / "chorjax"),
      "eval",
      str(run),
      "--data",
      "held-out",
      "--frames",
      str(frames),
    ]
    cmd += ["--num", "1", "--seeds", *map(str, seeds), "-o", str(out), *flags]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return {**figures(json.loads(out.read_text())), **({"chosen": chosen} if chosen else {})}


def summary(results: dict) -> str:
  """The table over training seeds: one row a recipe and draw (a run's name less its ", seed N"), each cell
  the mean and, with several seeds, [the least, the most]."""
  groups: dict = {}
  for run, variants in results.items():
    recipe = re.sub(r", seed \d+$", "", run)
    for variant, f in variants.items():
      groups.setdefault((recipe, variant), []).append(f)
  head = "| recipe | draw | seeds | " + " | ".join(HEADERS) + " |"
  lines = [head, "|" + "---|" * (3 + len(HEADERS))]
  for (recipe, variant), rows in sorted(groups.items()):
    cells = []
    for k in SUMMARY:
      v = [r[k] for r in rows]
      digits = 1 if k == "heldout_loss" else 2
      spread = f" [{min(v):.{digits}f}, {max(v):.{digits}f}]" if len(v) > 1 else ""
      cells.append(f"{np.mean(v):.{digits}f}{spread}")
    lines.append(f"| {recipe} | {variant} | {len(rows)} | " + " | ".join(cells) + " |")
  return "\n".join(lines)


SUMMARY = (
  "jitter",
  "speed",
  "root_travel",
  "movement_min",
  "movement_max",
  "fid_k",
  "fid_g",
  "root_step_max",
  "heldout_loss",
)
HEADERS = (
  "jitter",
  "speed",
  "root travel",
  "calmest 1,000",
  "busiest 1,000",
  "FID_k / train",
  "FID_g / train",
  "largest root step",
  "held-out NLL",
)


def table(results: dict) -> str:
  lines = [
    "| run | draw | jitter | speed | root travel | calmest / busiest 1,000 frames | FID_k / train | FID_g / train "
    "| largest root step | held-out NLL |",
    "|---|---|---|---|---|---|---|---|---|---|",
  ]
  for run, variants in sorted(results.items()):
    for variant, f in variants.items():
      lines.append(
        f"| {run} | {variant} | {f['jitter']:.2f} | {f['speed']:.2f} | {f['root_travel']:.2f} | "
        f"{f['movement_min']:.2f} / {f['movement_max']:.2f} | {f['fid_k']:.2f} | {f['fid_g']:.2f} | "
        f"{f['root_step_max']:.2f} | {f['heldout_loss']:.1f} |"
      )
  return "\n".join(lines)


def main() -> None:
  p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  p.add_argument("runs", nargs="*", type=Path)
  p.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=[*VARIANTS, *CALIBRATED_VARIANTS])
  p.add_argument("--frames", type=int, default=10_000)
  p.add_argument("--seeds", nargs="+", type=int, default=[0, 1])
  p.add_argument("--name", help="the name a run is recorded under (default: its folder's parent/name)")
  p.add_argument("--table", action="store_true", help="print the table of results.json as markdown")
  p.add_argument("--summary", action="store_true", help="print it over training seeds (mean and range)")
  args = p.parse_args()
  results = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
  if args.table or args.summary:
    print(summary(results) if args.summary else table(results))
    return
  for run in args.runs:
    name = args.name or f"{run.parent.name}/{run.name}"
    for variant in args.variants:
      if variant in results.get(name, {}):
        continue
      figures = measure(run, variant, args.frames, args.seeds)
      results = record(name, variant, figures)
      print(name, variant, figures, flush=True)


def record(name: str, variant: str, figures: dict) -> dict:
  """Adds one run's figures for one draw to ``results.json`` under a lock, merged with what the file holds now
  (several ablations may run side by side). Returns the whole file."""
  import fcntl

  with open(RESULTS.with_suffix(".lock"), "w") as lock:
    fcntl.flock(lock, fcntl.LOCK_EX)
    results = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    results.setdefault(name, {})[variant] = figures
    RESULTS.write_text(json.dumps(results, indent=1) + "\n")
  return results


if __name__ == "__main__":
  main()
