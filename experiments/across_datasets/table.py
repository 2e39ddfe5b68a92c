"""The comparisons users run, on every dataset of the dancers benchmark : one table per measure, a
row per configuration, a column per dataset; every figure on the dataset's held-out takes, mean (lowest-
highest) over the training seeds.

  .venv/bin/python experiments/across_datasets/table.py     # writes experiments/across_datasets/table.md

Reads, whichever are on this machine, the runs of experiments/dancers/sweep.toml as calibrated with the poses
measure (runs/dancers_poses), as first calibrated without it (runs/dancers) and calibrated again
past the grid's ends (runs/dancers_beyond), the LSTM cell's runs so calibrated (runs/dancers_lstm),
experiments/rnn_types/dancers.toml, experiments/mdn_vs_mse/dancers.toml and dancers_lstm.toml,
experiments/families/dancers.toml and
experiments/aclstm/ (its CPU runs in runs/aclstm_cpu). Each evaluated run's small files are copied beside its
experiment (``results/``), and the table falls back to them where the runs are not on this machine.
Filmstrips: the end of seed 0's first 10,000-frame dancer of each configuration whose runs are on this
machine, beside a held-out take (strip_DATASET_CONFIG.png; those drawn on an earlier machine stay).
"""

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent.parent))
from _results import end_strip, keep_small_files, real_strip

from chorjax.evaluation.scoring import mean_of
from chorjax.sampling.calibration_file import chosen_calibration_row

HERE = Path(__file__).parent.parent  # experiments/
OUT = Path(__file__).parent
DATASETS = ("cmu94", "salsa", "martial", "cmu05", "cmu131")
# (label, runs folder, the folder its results are kept in, what a run's name holds besides dataset and seed, slug)
CONFIGS = [
  (
    "LN-LSTM, MDN (the LN-LSTM quickstart)",
    "runs/dancers_poses",
    "dancers/results/dancers_poses",
    "",
    "quickstart",
  ),
  (
    "LN-LSTM, MDN, calibrated without the poses measure",
    "runs/dancers",
    "dancers/results/dancers",
    "",
    "quickstart17",
  ),
  (
    "LN-LSTM, MDN, calibrated past the grid's ends",
    "runs/dancers_beyond",
    "dancers/results/dancers_beyond",
    "",
    "quickstart_beyond",
  ),
  (
    "LSTM, MDN, calibrated past the grid's ends (the LSTM quickstart before four noise filters and pace 2)",
    "runs/dancers_lstm",
    "dancers/results/dancers_lstm",
    "",
    "lstm_beyond",
  ),
  ("LSTM, MDN", "runs/rnn_types_dancers", "rnn_types/results/rnn_types_dancers", "cell=lstm-", "lstm"),
  ("GRU, MDN", "runs/rnn_types_dancers", "rnn_types/results/rnn_types_dancers", "cell=gru-", "gru"),
  ("LN-LSTM, MSE", "runs/mdn_vs_mse_dancers", "mdn_vs_mse/results/mdn_vs_mse_dancers", "head=mse-", "mse"),
  (
    "LSTM, MSE (the LSTM quickstart's twin)",
    "runs/mdn_vs_mse_lstm",
    "mdn_vs_mse/results/mdn_vs_mse_lstm",
    "head=mse-",
    "mse_lstm",
  ),
  ("LSTM-GAN (experiments/families)", "runs/families_dancers", "families/results/families_dancers", "", "gan"),
  ("acLSTM, 3 x 1024 LSTM, MSE: 6 min on 2 CPU cores", "runs/aclstm_cpu", "aclstm/results/cpu", "", "aclstm_cpu"),
  ("acLSTM, 3 x 1024 LSTM, MSE: 4.5-6 min on an H200", "runs/aclstm_gpu", "aclstm/results/gpu", "", "aclstm_gpu"),
]


def FID_G(e: dict) -> float:
  return mean_of(e["fid_g"]) / mean_of(e["fid_g_train"])


def novelty(e: dict) -> float:
  return mean_of(e["novelty"]) / mean_of(e["novelty_real"])


# (label, value of one evaluation, the direction that is better: 'one' = nearer 1 on a log scale, 'low', 'high')
MEASURES = [
  ("FID_k / the training takes'", lambda e: mean_of(e["fid_k"]) / mean_of(e["fid_k_train"]), "low"),
  ("FID_g / the training takes'", FID_G, "low"),
  (
    "movement, worst 1,000-frame segment (1 = the held-out takes')",
    lambda e: min(mean_of(e["movement_min"]), 2 - mean_of(e["movement_max"])),
    "one",
  ),
  ("jitter (1 = the held-out takes')", lambda e: mean_of(e["jitter"]), "one"),
  ("mean joint speed (1 = the held-out takes')", lambda e: mean_of(e["speed"]), "one"),
  ("novelty / the held-out takes' (under 0.8: copying)", novelty, "high"),
  (
    "diversity: Div_g / the held-out takes' (far under 1: one phrase looped or a held pose)",
    lambda e: mean_of(e["div_g"]) / mean_of(e["div_g_real"]),
    "one",
  ),
]


def runs_of(runs: str, kept: str, holds: str, dataset: str) -> list[Path]:
  """The evaluated runs of one configuration on one dataset: on this machine, else their kept results."""
  for root in (Path(runs), HERE / kept):
    found = sorted(d for d in root.glob(f"*-{dataset}-{holds}seed=*") if (d / "eval" / "metrics.json").exists())
    if found:
      return found
  return []


def save_results() -> None:
  """Copies the small files of every evaluated run on this machine beside its experiment."""
  for _, runs, kept, holds, _ in CONFIGS:
    for dataset in DATASETS:
      for run in runs_of(runs, kept, holds, dataset):
        if not run.is_relative_to(HERE):
          keep_small_files(run, HERE / kept)


def spread(values: list[float]) -> str:
  v = np.asarray(values)
  return f"{v.mean():.2f} ({v.min():.2f}-{v.max():.2f})" if len(v) > 1 else f"{v[0]:.2f} (1 seed)"


def winner(cells: dict[str, list[float]], better: str) -> str | None:
  """The configuration whose every seed beats every seed of every other one with 3 seeds (None if the
  spreads overlap): a winner named only beyond the spread."""
  key = {"low": lambda x: x, "high": lambda x: -x, "one": lambda x: abs(np.log(x))}[better]
  full = {label: [key(x) for x in v] for label, v in cells.items() if len(v) >= 3}
  for label, v in full.items():
    if len(full) > 1 and all(max(v) < min(w) for other, w in full.items() if other != label):
      return label
  return None


def tables() -> list[str]:
  evaluated = {
    (label, dataset): [json.loads((d / "eval" / "metrics.json").read_text()) for d in runs_of(*where, dataset)]
    for label, *where, _ in CONFIGS
    for dataset in DATASETS
  }
  datasets = [d for d in DATASETS if any(evaluated[label, d] for label, *_ in CONFIGS)]
  out = []
  for title, f, better in MEASURES:
    out += [f"### {title}", "", "| configuration | " + " | ".join(datasets) + " |", "|---" * (len(datasets) + 1) + "|"]
    for label, *_ in CONFIGS:
      cells = [spread([f(e) for e in evaluated[label, d]]) if evaluated[label, d] else "" for d in datasets]
      if any(cells):
        out.append(f"| {label} | " + " | ".join(cells) + " |")
    wins = []
    for d in datasets:
      w = winner({label: [f(e) for e in evaluated[label, d]] for label, *_ in CONFIGS}, better)
      full = sum(len(evaluated[label, d]) >= 3 for label, *_ in CONFIGS)
      wins.append(w or ("spreads overlap" if full > 1 else "-"))
    out += ["| beyond the spread (3 seeds each) | " + " | ".join(wins) + " |", ""]
  return out


def selection() -> list[str]:
  """Would choosing, among a configuration's training seeds, the one whose calibrated draws' poses are nearest
  the training takes' (calibration.json's poses measure: no held-out take involved) pick the seed with the
  best held-out FID_g, and what does the choice cost elsewhere? One row per configuration and dataset with 3
  calibrated seeds; the last columns: the chosen seed's calmest 1,000 frames and FID_k, each beside the range
  over the seeds."""
  out = [
    "| configuration | dataset | poses measure on the training takes, by seed | held-out FID_g / train, by seed "
    "| the chosen seed's FID_g | mean over seeds | the chosen seed's calmest 1,000 frames (seeds) "
    "| its FID_k / train (seeds) |",
    "|---|---|---|---|---|---|---|---|",
  ]
  calm = MEASURES[2][1]
  for label, runs, kept, holds, _ in CONFIGS:
    for dataset in DATASETS:
      found = runs_of(runs, kept, holds, dataset)
      rows = [chosen_calibration_row(d) for d in found]
      if len(found) < 3 or any(r is None or "poses" not in r for r in rows):
        continue
      evals = [json.loads((d / "eval" / "metrics.json").read_text()) for d in found]
      fid = [FID_G(e) for e in evals]
      poses = [r["poses"] for r in rows if r is not None]
      pick = int(np.argmin(poses))
      others = []
      for f in (calm, MEASURES[0][1]):
        v = [f(e) for e in evals]
        others.append(f"{v[pick]:.2f} ({min(v):.2f}-{max(v):.2f})")
      out.append(
        f"| {label} | {dataset} | {', '.join(f'{p:.2f}' for p in poses)} | {', '.join(f'{f:.2f}' for f in fid)} "
        f"| {fid[pick]:.2f} | {np.mean(fid):.2f} | {' | '.join(others)} |"
      )
  return out


CELLS = ("LN-LSTM, MDN (the LN-LSTM quickstart)", "LSTM, MDN", "GRU, MDN")


def cell_selection() -> list[str]:
  """Would choosing among every calibrated MDN run of a dataset (the three cells x their training seeds) the one
  whose calibration objective is lowest (its chosen draws' distance from the training takes on all five
  measures: no held-out take involved) pick a run that dances like the held-out takes? One row per dataset
  where every cell has 3 calibrated seeds."""
  out = [
    "| dataset | runs | chosen: cell, seed | its calibration objective | its held-out FID_g / train "
    "| held-out FID_g of every run: best, median, worst |",
    "|---|---|---|---|---|---|",
  ]
  for dataset in DATASETS:
    runs = []
    for label, where, kept, holds, _ in CONFIGS:
      if label in CELLS:
        found = runs_of(where, kept, holds, dataset)
        runs += [(label, d, chosen_calibration_row(d)) for d in found] if len(found) >= 3 else []
    if len({label for label, *_ in runs}) < len(CELLS) or any(r is None for *_, r in runs):
      continue
    fid = [FID_G(json.loads((d / "eval" / "metrics.json").read_text())) for _, d, _ in runs]
    pick = int(np.argmin([r["objective"] for *_, r in runs if r is not None]))
    label, run, row = runs[pick]
    assert row is not None
    seed = run.name.rsplit("seed=", 1)[1]
    out.append(
      f"| {dataset} | {len(runs)} | {label.split(',')[0]}, seed {seed} | {row['objective']:.2f} | {fid[pick]:.2f} "
      f"| {min(fid):.2f}, {float(np.median(fid)):.2f}, {max(fid):.2f} |"
    )
  return out


def strips() -> list[str]:
  """Per dataset: the last 900 frames of seed 0's first evaluated dancer of each configuration run here,
  then a held-out take as training read it."""
  out = []
  for dataset in DATASETS:
    drawn, real_from = [], None
    for label, runs, _, holds, slug in CONFIGS:
      seed0 = [d for d in Path(runs).glob(f"*-{dataset}-{holds}seed=0") if (d / "eval" / "sample.npz").exists()]
      png = OUT / f"strip_{dataset}_{slug}.png"
      if seed0:
        end_strip(seed0[0] / "eval" / "sample.npz", png, f"{dataset}, {label}")
        real_from = real_from or seed0[0]
      if png.exists():
        drawn.append(f"![{dataset}, {label}]({png.name})")
    png = OUT / f"strip_{dataset}_real.png"
    if real_from is not None:
      real_strip(real_from, png, dataset)
    if drawn and png.exists():
      out += [f"### {dataset}", "", *(f"{x}\n" for x in drawn), f"![{dataset} real]({png.name})", ""]
  return out


if __name__ == "__main__":
  save_results()
  lines = [
    "# Every configuration on every dataset of the dancers benchmark",
    "",
    "Written by `experiments/across_datasets/table.py` from the runs of the comparisons' dancers sweeps: every figure on the",
    "dataset's held-out takes, 4 sampling seeds x 10,000 frames per run, mean (lowest-highest) over training",
    "seeds. A configuration is named beyond the spread only where every one of its 3 seeds beats every seed of",
    "every other configuration with 3 seeds.",
    "",
    "Machines: every run on an AMD EPYC machine's 2 CPU cores (jax 0.10.2), except those trained and scored on",
    "an NVIDIA H100 (its image's jax 0.11.2 / flax 0.12.10, 6-11 sweep processes side by side, 2026-11-26):",
    "GRU and LSTM on martial (the LSTM trained again on CPU for the calibrated row), the LN-LSTM's MSE twin on",
    "cmu05 (3 seeds) and cmu131 (seed 0), the LSTM's MSE twin (all), the LSTM-GAN on cmu94, martial seeds 1-2,",
    "cmu05 seed 2 and cmu131; and acLSTM's H200 row. Same configs, steps and",
    "evaluation on both; a GPU rounds differently, so a seed there is another draw of the same recipe. cmu05",
    "holds one short held-out take: its FID_k reference (the training takes' own FID_k) is 9,272 +- 9,062 over",
    "the draws, so its FID_k column is not read; its FID_g is.",
    "",
    *tables(),
    "## Choosing among training seeds by the calibration's poses measure",
    "",
    selection.__doc__.split("\n\n")[0].replace("\n  ", " ") if selection.__doc__ else "",
    "",
    *selection(),
    "",
    "## Choosing the cell too, by the calibration's objective",
    "",
    cell_selection.__doc__.split("\n\n")[0].replace("\n  ", " ") if cell_selection.__doc__ else "",
    "",
    *cell_selection(),
    "",
    "## The end of a 10,000-frame dancer (seed 0) beside a held-out take",
    "",
    *strips(),
  ]
  (OUT / "table.md").write_text("\n".join(lines))
  print(f"wrote {OUT / 'table.md'}", file=sys.stderr)
