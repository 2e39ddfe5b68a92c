"""The dancers benchmark's summary: one row per dataset and recipe, every figure judged on the held-out
takes; and, per dataset, the end of a generated dance beside a held-out take (filmstrips).

  .venv/bin/python experiments/dancers/table.py > experiments/dancers/table.md

Reads (VARIANTS): runs/dancers/dancers-* (the quickstart recipe as shipped), runs/dancers_learned/learned-*
(the same runs kept at their best validation checkpoint and calibrated: experiments/dancers/learned.py),
runs/dancers_best/best-* (best.toml: trained with train.keep = "best" and train.calibrate), runs/dancers_cal5/
cal5-* (those runs calibrated again with five controls and four measures: learned.py runs/dancers_best
runs/dancers_cal5 cal5-), runs/dancers_pca/pca-* (pca.toml: the same with the MDN in the principal axes),
runs/dancers_pca_wide/wide-* (those calibrated again with scale temperatures 0.7 and 0.8 added to the grid),
runs/dancers_ground/ground-* (copies of the pca runs evaluated with --ground, their calibration kept) and
runs/dancers_steps/steps-* (the same with --ground --clamp-steps; experiments/dancers/README.md says how) and
runs/dancers_pcag/pcag-* (pca_ground.toml: trained and calibrated with sample.ground and sample.clamp_steps on).
"""

import json
from pathlib import Path

import numpy as np

from chorjax.scoring import mean_of

HERE = Path(__file__).parent
VARIANTS = {
  "as shipped": Path("runs/dancers"),
  "kept at best of 4 checkpoints + calibrated": Path("runs/dancers_learned"),
  "train.keep best + train.calibrate (2 controls)": Path("runs/dancers_best"),
  "train.keep best + calibrate 5 controls, 4 measures": Path("runs/dancers_cal5"),
  "the same + model.mdn_basis = pca": Path("runs/dancers_pca"),
  "pca, calibrated with scale temperature 0.7-1.2": Path("runs/dancers_pca_wide"),
  "pca + --ground (the pca calibration)": Path("runs/dancers_ground"),
  "pca + --ground --clamp-steps": Path("runs/dancers_steps"),
  "pca_ground.toml (ground, clamp_steps on while calibrating)": Path("runs/dancers_pcag"),
}
SLUG = dict(
  zip(
    VARIANTS,
    (
      "shipped",
      "copy_best_calibrated",
      "keep_best_calibrate",
      "keep_best_calibrate5",
      "pca",
      "pca_wide",
      "pca_ground",
      "pca_steps",
    ),
  )
)
# the variants whose end frames are drawn beside a real take (the others' strips from earlier reports stay)
STRIPS = ("as shipped", "train.keep best + calibrate 5 controls, 4 measures", "pca + --ground --clamp-steps")
DATASETS = ("cmu94", "salsa", "martial", "cmu05", "cmu131")
# (label, value of one evaluation, how a row's worst seed is picked: the one farthest from the bar)
COLUMNS = [
  (
    "movement, worst 1,000-frame segment",
    lambda e: min(mean_of(e["movement_min"]), 2 - mean_of(e["movement_max"])),
    min,
  ),
  ("jitter", lambda e: mean_of(e["jitter"]), lambda v: max(v, key=lambda x: abs(np.log(x)))),
  ("speed", lambda e: mean_of(e["speed"]), lambda v: max(v, key=lambda x: abs(np.log(x)))),
  ("root travel", lambda e: mean_of(e["root_travel"]), lambda v: max(v, key=lambda x: abs(np.log(x)))),
  ("root step max", lambda e: mean_of(e["root_step_max"]), max),
  ("FID_k / train takes'", lambda e: mean_of(e["fid_k"]) / mean_of(e["fid_k_train"]), max),
  ("FID_g / train takes'", lambda e: mean_of(e["fid_g"]) / mean_of(e["fid_g_train"]), max),
  ("novelty / held-out takes'", lambda e: mean_of(e["novelty"]) / mean_of(e["novelty_real"]), min),
  ("airborne, % of frames", lambda e: 100 * mean_of(e["airborne"]) if "airborne" in e else None, max),
]


def _two_controls(run: Path) -> bool:
  """Whether a best.toml run was calibrated as best.toml's first pass was (noise smoothing and scale
  temperature; runs trained after 2026-11-25 calibrated five controls: their row is the cal5 one)."""
  path = run / "calibration.json"
  return path.exists() and len(json.loads(path.read_text())["settings"]) == 2


def evaluations(root: Path, dataset: str) -> list[tuple[Path, dict]]:
  runs = sorted(d for d in root.glob(f"*-{dataset}-seed=*") if (d / "eval" / "metrics.json").exists())
  if root == VARIANTS["train.keep best + train.calibrate (2 controls)"]:
    runs = [d for d in runs if _two_controls(d)]
  return [(d, json.loads((d / "eval" / "metrics.json").read_text())) for d in runs]


def cell(values, worst) -> str:
  if any(x is None for x in values):
    return "-"  # evaluated before the measure existed
  v = np.asarray(values)
  return f"{v.mean():.2f} ± {v.std(ddof=1):.2f} ({worst(list(v)):.2f})" if len(v) > 1 else f"{v[0]:.2f}"


def table() -> list[str]:
  head = ["dataset", "recipe", "runs", *[c[0] for c in COLUMNS], "held-out NLL kept - best"]
  lines = ["| " + " | ".join(head) + " |", "|---" * len(head) + "|"]
  for dataset in DATASETS:
    for variant, root in VARIANTS.items():
      evs = evaluations(root, dataset)
      if not evs:
        continue
      cells = [cell([f(e) for _, e in evs], worst) for _, f, worst in COLUMNS]
      gap = [
        e["heldout_loss"]
        - min(r["val_loss"] for r in map(json.loads, (d / "metrics.jsonl").read_text().splitlines()) if "val_loss" in r)
        for d, e in evs
      ]
      lines.append(f"| {dataset} | {variant} | {len(evs)} | " + " | ".join(cells) + f" | {cell(gap, max)} |")
  return lines


def strips() -> list[str]:
  """Per dataset: the end of the first evaluated dancer of seed 0 (as shipped, and best + calibrated)
  beside a held-out take, as training read it."""
  from chorjax.data.npz import read_npz
  from chorjax.render.plot import plot_strip
  from chorjax.run import load_run, read_reference

  out = []
  for dataset in DATASETS:
    runs = {
      v: next((d for d, _ in evaluations(r, dataset) if d.name.endswith("seed=0")), r / "-")
      for v, r in VARIANTS.items()
      if v in STRIPS
    }
    runs = {v: r for v, r in runs.items() if (r / "eval" / "sample.npz").exists()}
    if "as shipped" not in runs:
      continue
    out += [f"### {dataset}", ""]
    for variant, run in runs.items():
      dance = read_npz(run / "eval" / "sample.npz")[0]
      end = dance.replace(positions=dance.positions[-900:], name=f"{dataset} {variant}: frames 9,100-10,000")
      png = HERE / f"strip_{dataset}_{SLUG[variant]}.png"
      plot_strip(end, png, every=10, poses=12)
      out += [f"![{dataset} {variant}]({png.name})", ""]
    real = read_reference(load_run(runs["as shipped"]), ["held-out"])[0][0]
    png = HERE / f"strip_{dataset}_real.png"
    plot_strip(real.replace(name=f"{dataset} held-out take {real.name}"), png, every=10, poses=12)
    out += [f"![{dataset} real]({png.name})", ""]
  return out


if __name__ == "__main__":
  print("\n".join(table() + [""] + strips()))
