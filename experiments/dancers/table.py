"""The dancers benchmark's summary: one row per dataset and recipe, every figure judged on the held-out
takes; and, per dataset, the end of a generated dance beside a held-out take (filmstrips).

  .venv/bin/python experiments/dancers/table.py > experiments/dancers/table.md
  .venv/bin/python experiments/dancers/table.py --readme    # the README's table (the quickstart per dataset)

Reads (VARIANTS), whichever are on this machine: runs/dancers/dancers-* (sweep.toml until session 25: the LN-LSTM
quickstart of 2026-11-25, its cmu94 and martial held out by name), and the variants measured on the way there
(their runs were on the machine of 2026-11-25; their rows are
in table_2026-11-25.md): runs/dancers_learned/learned-* (the old quickstart's runs kept at their best validation
checkpoint and calibrated: experiments/dancers/learned.py), runs/dancers_best/best-* (best.toml),
runs/dancers_cal5/cal5-* (those calibrated again with five controls and four measures: learned.py
runs/dancers_best runs/dancers_cal5 cal5-), runs/dancers_pca/pca-* (pca.toml), runs/dancers_pca_wide/wide-*
(those calibrated with scale temperatures 0.7 and 0.8 added), runs/dancers_ground/ground-* and
runs/dancers_steps/steps-* (copies of the pca runs evaluated with --ground, and --ground --clamp-steps;
experiments/dancers/README.md says how); runs/dancers_w128/w128-* (window128.toml: windows of 128 frames); and
runs/dancers_poses/poses-* (the quickstart's runs calibrated again with the poses measure of 2026-11-26:
learned.py runs/dancers runs/dancers_poses poses-), runs/dancers_beyond/beyond-* (those calibrated past the
grid's ends), runs/dancers_lstm/lstm-* (the cells' sweep's LSTM runs so calibrated) and
runs/dancers_paced/paced-* (those judged again once `sample.ground` moved the body no faster than the takes'
fastest vertical root step, 2026-11-26, session 23), runs/dancers_feedback/feedback-* (feedback.toml: trained with
scheduled sampling, session 24), runs/dancers_fbdrop/fbdrop-* (feedback_dropout.toml: the same keeping dropout)
runs/dancers_split/split-* (sweep.toml since session 25: the quickstart judged on held-out takes that its
dancer's own training takes pass the bars against; a real row precedes the first recipe judged on each split)
and runs/dancers_order4/* (those runs, and the paced cmu05 / cmu131 runs, calibrated again with the noise
through four filters, `chorjax calibrate RUN --noise-order 4`, session 26: experiments/dancers/README.md);
session 27 (2026-11-27): runs/dancers_h100_p05/* (sweep.toml trained again on a lent H100, calibrated and judged
here as the quickstart of session 26 did: pace 0.5, the governor measuring the pose features),
runs/dancers_h100/* (the same checkpoints calibrated and judged with the governor holding the judge's own
measure at pace 2: `chorjax calibrate RUN --pace 2`), runs/dancers_hold/* (copies of them calibrated and judged
once the governor also let go of the component off pace: the quickstart since) and runs/dancers_fbh100/*
(martial trained with scheduled sampling, dropout 0, on the H100; calibrated as runs/dancers_h100);
session 28: runs/dancers_pool/* (copies of runs/dancers_hold calibrated again once calibration pooled speed and
root travel over the reference's frames as eval does) and runs/dancers_obj/* (calibrated again once the
objective counted the farthest rate twice: the quickstart since) and runs/dancers_cpu/* (cpu_martial.toml and
cpu_others.toml: martial, cmu94 and salsa trained here with the quickstart as shipped, training seeds 3-5;
cpu_martial_more.toml: martial's 6-11) and runs/dancers_parts/* (parts.toml, parts_more.toml and
parts_martial.toml: the quickstart trained with train.batch_parts = 2 on CPU, seeds 0-2, 3-5 and martial's 6-11).
Each evaluated run's small files (config, calibration, metrics log, eval metrics) are copied to results/, and
the table reads them beside the runs on this machine (a run here before its kept copy).
"""

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent.parent))
from _results import end_strip, keep_small_files, real_strip, takes_as_trained

from chorjax.evaluation.scoring import mean_of

HERE = Path(__file__).parent
RESULTS = HERE / "results"  # each run's small files, kept in the repository (runs/ is not)
VARIANTS = {
  "quickstart": Path("runs/dancers"),
  "kept at best of 4 checkpoints + calibrated": Path("runs/dancers_learned"),
  "train.keep best + train.calibrate (2 controls)": Path("runs/dancers_best"),
  "train.keep best + calibrate 5 controls, 4 measures": Path("runs/dancers_cal5"),
  "the same + model.mdn_basis = pca": Path("runs/dancers_pca"),
  "pca, calibrated with scale temperature 0.7-1.2": Path("runs/dancers_pca_wide"),
  "pca + --ground (the pca calibration)": Path("runs/dancers_ground"),
  "pca + --ground --clamp-steps": Path("runs/dancers_steps"),
  "quickstart, windows of 128 frames at batch 16": Path("runs/dancers_w128"),
  "quickstart, calibrated with the poses measure": Path("runs/dancers_poses"),
  "the same, calibrated past the grid's ends": Path("runs/dancers_beyond"),
  "the same with model.cell = lstm": Path("runs/dancers_lstm"),
  "the same, the ground shift paced": Path("runs/dancers_paced"),
  "the same, trained with scheduled sampling": Path("runs/dancers_feedback"),
  "the same, scheduled sampling with dropout 0.2": Path("runs/dancers_fbdrop"),
  "the quickstart, judged on the held-out takes split.py chooses": Path("runs/dancers_split"),
  "the same, its noise through four filters (sample.noise_order = 4)": Path("runs/dancers_order4"),
  "the same trained again on an H100 (pace 0.5, the governor on pose features)": Path("runs/dancers_h100_p05"),
  "those runs, the governor holding the judge's measure at pace 2": Path("runs/dancers_h100"),
  "the same, off pace the governor letting go of the component": Path("runs/dancers_hold"),
  "the H100 runs, martial trained with scheduled sampling, dropout 0 (pace 2, scale alone)": Path(
    "runs/dancers_fbh100"
  ),
  "the H100 runs as shipped, calibration pooling speed and root travel as eval does": Path("runs/dancers_pool"),
  "the same, the farthest rate counted twice in the objective": Path("runs/dancers_obj"),
  "the quickstart as shipped, trained on CPU, training seeds 3-5, martial 3-11 (cpu_*.toml)": Path("runs/dancers_cpu"),
  "the quickstart trained with train.batch_parts = 2 on CPU, seeds 0-5, martial 0-11 (parts*.toml)": Path(
    "runs/dancers_parts"
  ),
}
SLUG = dict(
  zip(
    VARIANTS,
    (
      "quickstart",
      "copy_best_calibrated",
      "keep_best_calibrate",
      "keep_best_calibrate5",
      "pca",
      "pca_wide",
      "pca_ground",
      "pca_steps",
      "w128",
      "poses",
      "beyond",
      "lstm",
      "paced",
      "feedback",
      "fbdrop",
      "split",
      "order4",
      "h100_p05",
      "h100",
      "hold",
      "fbh100",
      "pool",
      "shipped",
      "cpu",
      "parts",
    ),
  )
)
# the variant whose end frames are drawn beside a real take (the README's pictures)
STRIPS = ("the same, the farthest rate counted twice in the objective",)  # the quickstart as shipped
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


def save_results() -> None:
  """Copies the small files of every evaluated run of every variant on this machine to
  ``RESULTS/<variant folder>/<run>`` (what ``evaluations`` reads where the runs are not on the machine)."""
  for root in VARIANTS.values():
    for run in sorted(root.glob("*-seed=*")):
      if (run / "eval" / "metrics.json").exists():
        keep_small_files(run, RESULTS / root.name)


def evaluations(root: Path, dataset: str) -> list[tuple[Path, dict]]:
  """A variant's evaluated runs of ``dataset``: those on this machine, and the kept small files of the others."""
  found = {}
  for where in (RESULTS / root.name, root):  # a run on this machine before its kept copy
    found.update({d.name: d for d in where.glob(f"*-{dataset}-seed=*") if (d / "eval" / "metrics.json").exists()})
  runs = [found[name] for name in sorted(found)]
  if root == VARIANTS["train.keep best + train.calibrate (2 controls)"]:
    runs = [d for d in runs if _two_controls(d)]
  return [(d, json.loads((d / "eval" / "metrics.json").read_text())) for d in runs]


def cell(values, worst) -> str:
  if any(x is None for x in values):
    return "-"  # evaluated before the measure existed
  v = np.asarray(values)
  return f"{v.mean():.2f} ± {v.std(ddof=1):.2f} ({worst(list(v)):.2f})" if len(v) > 1 else f"{v[0]:.2f}"


def real_takes(run: Path) -> tuple[list, list, object, float]:
  """``(training takes, held-out takes, skeleton, fps)`` of a run, y-up, read as its training read them
  (from its config.json alone: no checkpoint needed)."""
  from chorjax.data.transforms import to_y_up

  ds, every = takes_as_trained(run)
  y_up = lambda names: [np.asarray(to_y_up(every[n].positions, ds.features.up_axis)) for n in names]
  return y_up(ds.train_names), y_up(ds.val_names), ds.features.skeleton, ds.fps


def real_scores(run: Path) -> tuple[dict, tuple[int, float]]:
  """The run's training takes scored as a sample against its held-out takes (FID over themselves, so the
  FID ratios are 1), and ``(how many training takes, their minutes)``. Their calmest and busiest segment
  are the extremes over every take's segments (``movement_min_train`` / ``movement_max_train``), as a
  sample's are over its own: not the takes' mean of each take's (which hid martial's 0.66 and 1.40 takes
  behind 0.96 / 0.99 until 2026-11-26)."""
  from chorjax.evaluation.scoring import score

  train, held, skeleton, fps = real_takes(run)
  e = score(train, held, skeleton, fps, train=train, unseen=held)  # its fid_*_train are its fid_k / fid_g
  e["movement_min"], e["movement_max"] = e["movement_min_train"], e["movement_max_train"]
  return e, (len(train), sum(map(len, train)) / fps / 60)


def held_out_names(run: Path) -> str:
  """The run's held-out (validation) takes, as its config names them."""
  return ", ".join(json.loads((run / "config.json").read_text())["data"]["val_takes"])


def real_row(dataset: str, run: Path) -> str:
  """The dataset's training takes scored as if they were a sample against its held-out takes (those of
  ``run``'s split): what real dance by this dancer scores on each column (FID ratios are 1 by construction;
  novelty has no meaning)."""
  e, _ = real_scores(run)
  cells = [cell([f(e)], worst) if "novelty" not in label else "-" for label, f, worst in COLUMNS]
  label = f"real: the training takes as a sample (held out: {held_out_names(run)})"
  return f"| {dataset} | {label} | - | " + " | ".join(cells) + " | - |"


README_COLUMNS = [
  ("calmest / busiest 1,000 frames", None),
  ("jitter", lambda e: mean_of(e["jitter"])),
  ("speed", lambda e: mean_of(e["speed"])),
  ("root travel", lambda e: mean_of(e["root_travel"])),
  ("largest root step", lambda e: mean_of(e["root_step_max"])),
  ("FID_k / train takes'", lambda e: mean_of(e["fid_k"]) / mean_of(e["fid_k_train"])),
  ("FID_g / train takes'", lambda e: mean_of(e["fid_g"]) / mean_of(e["fid_g_train"])),
  ("airborne %", lambda e: 100 * mean_of(e["airborne"])),
]


def _spread(values) -> str:
  """``mean (lowest-highest)`` over the training seeds."""
  v = np.asarray(values)
  return f"{v.mean():.2f} ({v.min():.2f}-{v.max():.2f})" if len(v) > 1 else f"{v[0]:.2f}"


def _seconds(run: Path) -> float:
  """Training + calibration wall time of a run on this machine (config.json written -> calibration.json)."""
  return (run / "calibration.json").stat().st_mtime - (run / "config.json").stat().st_mtime


def readme_table() -> list[str]:
  """The README's table: per dataset, real dance and the quickstart (mean and range over training seeds)."""
  head = ["dataset (motion trained on)", "", *[c[0] for c in README_COLUMNS], "train + calibrate"]
  lines = ["| " + " | ".join(head) + " |", "|---" * len(head) + "|"]
  for dataset in DATASETS:
    # the quickstart as shipped (the LSTM cell, calibrated past the grid's ends, the ground shift paced), else
    # its latest earlier form
    shipped = [
      ("the same, the farthest rate counted twice in the objective", " (trained on an H100)"),
      ("the same, off pace the governor letting go of the component", " (trained on an H100, the objective before)"),
      ("those runs, the governor holding the judge's measure at pace 2", " (the governor on the scale alone)"),
      ("the same, its noise through four filters (sample.noise_order = 4)", " (pace 0.5 on pose features)"),
      ("the quickstart, judged on the held-out takes split.py chooses", " (noise through two filters)"),
      ("the same, the ground shift paced", ""),
      ("the same with model.cell = lstm", " (before the ground shift was paced)"),
      ("the same, calibrated past the grid's ends", " (the LN-LSTM cell)"),
      ("quickstart, calibrated with the poses measure", " (the LN-LSTM cell, calibrated before the walk)"),
      ("quickstart", " (the LN-LSTM cell, calibrated before the poses measure)"),
    ]
    found = ((v, w, evaluations(VARIANTS[v], dataset)) for v, w in shipped)  # read until one has runs
    variant, said, evs = next((f for f in found if f[2]), (None, "", []))
    if variant is None:
      continue
    e, (takes, minutes) = real_scores(evs[0][0])
    name = f"{dataset} ({takes} takes, {minutes:.1f} min; held out: {held_out_names(evs[0][0])})"

    def seg(es):  # the calmest segment's mean (lowest) / the busiest's mean (highest) over the seeds
      low, high = [np.array([mean_of(x[k]) for x in es]) for k in ("movement_min", "movement_max")]
      if len(es) == 1:
        return f"{low[0]:.2f} / {high[0]:.2f}"
      return f"{low.mean():.2f} ({low.min():.2f}) / {high.mean():.2f} ({high.max():.2f})"

    real = [seg([e])] + [f"{f(e):.2f}" for _, f in README_COLUMNS[1:]]
    lines.append(f"| {name} | real | " + " | ".join(real) + " | |")
    runs = [d for d, _ in evs]
    cells = [seg([x for _, x in evs])] + [_spread([f(x) for _, x in evs]) for _, f in README_COLUMNS[1:]]
    live = variant == "quickstart" and all(
      (d / "calibration.json").exists() and d.is_relative_to(Path("runs")) for d in runs
    )
    took = f"{min(map(_seconds, runs)) / 60:.1f}-{max(map(_seconds, runs)) / 60:.1f} min" if live else ""
    label = f"quickstart, {len(evs)} seeds{said}"
    lines.append(f"| | {label} | " + " | ".join(cells) + f" | {took} |")
  return lines


def table() -> list[str]:
  head = ["dataset", "recipe", "runs", *[c[0] for c in COLUMNS], "held-out NLL kept - best"]
  lines = ["| " + " | ".join(head) + " |", "|---" * len(head) + "|"]
  for dataset in DATASETS:
    splits = set()  # a real row before the first recipe judged on each split
    for variant, root in VARIANTS.items():
      evs = evaluations(root, dataset)
      if not evs:
        continue
      split = held_out_names(evs[0][0])
      if split not in splits:
        splits.add(split)
        lines.append(real_row(dataset, evs[0][0]))
      cells = [cell([f(e) for _, e in evs], worst) for _, f, worst in COLUMNS]
      gap = [
        e["heldout_loss"]
        - min(r["val_loss"] for r in map(json.loads, (d / "metrics.jsonl").read_text().splitlines()) if "val_loss" in r)
        for d, e in evs
      ]
      lines.append(f"| {dataset} | {variant} | {len(evs)} | " + " | ".join(cells) + f" | {cell(gap, max)} |")
  return lines


def strips() -> list[str]:
  """Per dataset: the end of the first evaluated dancer of seed 0 (of each variant in ``STRIPS`` run here)
  beside a held-out take, as training read it; drawn where the run's sample is on this machine, else the
  pictures drawn before."""
  out = []
  for dataset in DATASETS:
    runs = {
      v: next((d for d, _ in evaluations(r, dataset) if d.name.endswith("seed=0")), r / "-")
      for v, r in VARIANTS.items()
      if v in STRIPS
    }
    pictures = {v: HERE / f"strip_{dataset}_{SLUG[v]}.png" for v in runs}
    real = HERE / f"strip_{dataset}_real.png"
    here = {v: r for v, r in runs.items() if (r / "eval" / "sample.npz").exists()}
    for variant, run in here.items():
      end_strip(run / "eval" / "sample.npz", pictures[variant], f"{dataset} {variant}")
    if here:
      real_strip(next(iter(here.values())), real, dataset)
    shown = [*((f"{dataset} {v}", png) for v, png in pictures.items()), (f"{dataset} real", real)]
    if all(png.exists() for _, png in shown):
      out += [f"### {dataset}", ""] + [line for alt, png in shown for line in (f"![{alt}]({png.name})", "")]
  return out


if __name__ == "__main__":
  save_results()
  if sys.argv[1:] == ["--readme"]:
    print("\n".join(readme_table()))
    sys.exit()
  print("\n".join(table() + [""] + strips()))
