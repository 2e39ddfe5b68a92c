"""``chorjax compare``: the comparison report of trained runs (a sweep's points, or any): runs that differ only
in their training seed grouped, each column's mean +- sd over seeds, the winner named only beyond that spread
and per dataset, the loss curves and movement plots, and filmstrips of their samples
(``docs/guides/sweeps.md``)."""

from __future__ import annotations

import datetime
import json
import os
import platform
import re
from pathlib import Path

import jax
import numpy as np

from chorjax.data.npz import read_npz
from chorjax.errors import UserError, atomic_write, load_json, refuse_existing
from chorjax.evaluation.evaluate import metrics_path, sample_path
from chorjax.evaluation.scoring import mean_of
from chorjax.families import family_of
from chorjax.render.plot import plot_strip, require_matplotlib, save_figure
from chorjax.runtime import cpu_info
from chorjax.sampling.calibration_file import chosen_calibration_row
from chorjax.sampling.controls import Controls
from chorjax.sections import SampleConfig
from chorjax.training.driver import metrics_row

# metric -> (label, how to pick the winner)
COLUMNS = [
  ("heldout_loss", "held-out loss", "min"),
  ("movement_first", "movement first segment", "one"),
  ("movement_last", "movement last segment", "one"),
  ("movement_min", "movement worst segment", "worst"),
  ("jitter", "jitter", "one"),
  ("bone_cv_mean", "bone CV mean", "min"),
  ("root_step_max", "root step max", "min"),
  ("foot_sliding", "foot slide", "data:data_foot_sliding"),
  ("pfc", "PFC", "data:data_pfc"),
  ("airborne", "airborne", "data:airborne_real"),
  ("fid_k", "FID_k / real", "real"),
  ("fid_g", "FID_g / real", "real"),
  ("fid_k", "FID_k / train takes'", "train"),
  ("fid_g", "FID_g / train takes'", "train"),
  ("speed", "speed", "one"),
  ("root_travel", "root travel", "one"),
  ("div_k", "Div_k", "data:div_k_real"),
  ("novelty", "novelty", "data:novelty_real"),
]
# what "best" means per rule; the value shown for "real" columns is FID / the real halves' FID
RULES = {
  "min": "lowest",
  "one": "closest to 1 (the data's)",
  "worst": "worst segment closest to 1",
  "real": "lowest relative to the real data's own FID",
  "train": "lowest relative to the training takes' FID against the held-out takes",
  "data": "closest to the real data's value",
}


def upgrade(result: dict) -> dict:
  """An evaluation file's metrics as today's are read: compatibility with files written before, in one place.
  Older files named the first and last segment ``movement_first_1000`` and ``movement_last_1000``, and lack
  the sampling controls added since (they were off)."""
  out = dict(result)
  for old, new in (("movement_first_1000", "movement_first"), ("movement_last_1000", "movement_last")):
    if old in out and new not in out:
      out[new] = out.pop(old)
  out.setdefault("segment_frames", 1000)
  if "sampling" in out:
    out["sampling"] = {**Controls.resolve(SampleConfig()).to_dict(), **out["sampling"]}
  return out


def machine_info() -> str:
  """CPU model, core count and library versions, for reports and benchmarks."""
  cpu = cpu_info().get("model name") or platform.processor() or platform.machine()
  return (
    f"{cpu}, {os.cpu_count()} cores, {jax.devices()[0].platform}; Python {platform.python_version()}, "
    f"jax {jax.__version__}"
  )


def _read_run(workdir: Path) -> dict:
  cfg_path, ev_path = workdir / "config.json", metrics_path(workdir)
  if not cfg_path.exists():
    raise UserError(f"{workdir}: not a run directory (no config.json)")
  if not ev_path.exists():
    raise UserError(f"{ev_path}: missing; run `chorjax eval {workdir} --data ...` first")

  history = workdir / "metrics.jsonl"
  rows = (
    [r for l in history.read_text(errors="replace").splitlines() if (r := metrics_row(l))] if history.exists() else []
  )
  evaluation = upgrade(_json_file(ev_path, "evaluation", f"run `chorjax eval {workdir} --data ... --force` again"))
  missing = [k for k in EVAL_NEEDS if k not in evaluation]
  if missing:
    raise UserError(f"{ev_path}: not a whole evaluation (no {missing[0]!r}); run `chorjax eval {workdir} ... --force`")
  return {
    "name": workdir.name,
    "dir": workdir,
    "config": _json_file(cfg_path, "run config", "the run directory is damaged"),
    "eval": evaluation,
    "history": rows,
    "calibration": _calibration_objective(workdir),
  }


def _calibration_objective(workdir: Path) -> float | None:
  """The objective of the settings a run's calibration chose (how far its draws are from its training takes
  on movement, jitter, speed, root travel and poses); None if never calibrated or hand-edited."""
  row = chosen_calibration_row(workdir)
  try:
    return None if row is None else float(row["objective"])
  except (KeyError, TypeError, ValueError):
    raise UserError(f"{workdir}: damaged calibration; run `chorjax calibrate {workdir}` again (or delete it)") from None


EVAL_NEEDS = ("frames", "num", "data", "sampling", "segment_frames", "movement_curve", "movement_min", "jitter")


def _json_file(path: Path, what: str, fix: str) -> dict:
  """A JSON object from ``path``, or one line saying it is damaged and what to do."""
  try:
    value = load_json(path.read_text(errors="replace"))
  except json.JSONDecodeError as e:
    raise UserError(f"{path}: damaged {what} (not JSON: {e.msg} at line {e.lineno}); {fix}") from None
  if not isinstance(value, dict):
    raise UserError(f"{path}: damaged {what} (not a JSON object); {fix}")
  return value


def _value(ev: dict, key: str, rule: str) -> float:
  """The number a table cell shows for one run."""
  if rule in ("real", "train"):
    return mean_of(ev[key]) / mean_of(ev[f"{key}_{rule}"])
  if rule == "worst":  # the segment farthest from the data's movement, low or high
    return max(mean_of(ev["movement_min"]), mean_of(ev["movement_max"]), key=lambda v: abs(v - 1.0))
  return mean_of(ev[key])


def _badness(ev: dict, key: str, rule: str) -> float:
  """How far one run is from the best possible value (lower is better)."""
  v = _value(ev, key, rule)
  if rule in ("one", "worst"):
    return abs(v - 1.0)
  if rule.startswith("data:"):
    return abs(v - mean_of(ev[rule.split(":")[1]]))
  return v


def _stats(values) -> tuple[float, float]:
  v = np.asarray(values, np.float64)
  return float(v.mean()), float(v.std(ddof=1)) if len(v) > 1 else 0.0


def group_runs(runs) -> list[dict]:
  """Runs whose configs differ only in ``train.seed`` and whose names agree but for ``seed=N`` form one group
  (named so): the same config under another name (another code version, say) is a row of its own.

  What a run was sampled with is what its evaluation records (``eval.sampling``), not its config's
  ``[sample]`` (``chorjax eval`` may override it): groups compare that, and ignore ``[sample]`` and ``[log]``.
  """
  groups: dict[str, dict] = {}
  for r in runs:
    cfg = {k: v for k, v in r["config"].items() if k not in ("name", "sample", "log")}
    cfg["train"] = {k: v for k, v in cfg["train"].items() if k != "seed"}
    drawn = {k: v for k, v in r["eval"].get("sampling", {}).items() if k not in ("seed", "seeds")}
    name = re.sub(r"-?\bseed=-?\d+", "", r["name"]).strip("-") or r["name"]
    ident = json.dumps([name, cfg, r["eval"].get("data"), drawn], sort_keys=True)
    groups.setdefault(ident, {"name": name, "runs": []})["runs"].append(r)
  out = list(groups.values())
  for g in out:
    if len(g["runs"]) == 1:
      g["name"] = g["runs"][0]["name"]
  return out


def _loss_takes(e: dict) -> str:
  """Which takes an evaluation's held-out loss was measured on (``evaluate.held_out``); evaluations from
  before the key measured it on every ``--data`` take: ``"all"``."""
  return e.get("loss_takes", "all")


def _needs(key: str, rule: str) -> list[str]:
  """The keys an evaluation must hold for a cell of ``key`` under ``rule``."""
  if rule.startswith("data:"):
    return [key, rule.split(":")[1]]
  return [key, f"{key}_train"] if rule == "train" else [key]


def _winner(groups, key, rule):
  """``(group or None, reason)``: the best group, named only where it beats the next beyond the spread."""
  needs = _needs(key, rule)
  rows = [g for g in groups if all(r["eval"].get(k) is not None for r in g["runs"] for k in needs)]
  if key == "heldout_loss" and len({r["eval"]["loss_kind"] for g in rows for r in g["runs"]}) > 1:
    return None, "not comparable (NLL vs MSE)"
  if key == "heldout_loss" and len({_loss_takes(r["eval"]) for g in rows for r in g["runs"]}) > 1:
    return None, "not comparable (some on held-out takes, some on the runs' training takes)"
  if not rows:
    return None, ""
  scored = sorted(
    ((_stats([_badness(r["eval"], key, rule) for r in g["runs"]]), g["name"], g) for g in rows), key=lambda x: x[0][0]
  )
  why = RULES[rule.split(":")[0]]
  if len(scored) == 1:
    return scored[0][2], why
  (best, sd_best), _, g = scored[0]
  (second, sd_second), _, runner_up = scored[1]
  if min(len(grp["runs"]) for _, _, grp in scored[:2]) < 2:
    return g, f"{why}; one run: spread unknown"
  if best + sd_best >= second - sd_second:
    values = f"{g['name']} {_cell(g, key, rule)} vs {runner_up['name']} {_cell(runner_up, key, rule)}"
    return None, f"within noise ({values})"
  return g, why


def _loss_plot(plt, runs, path: Path) -> None:
  fig, ax = plt.subplots(figsize=(8, 4))
  for r in runs:
    if not family_of(r["config"]).likelihood:  # adversarial losses are no likelihood: not on this axis
      continue
    steps = [h["step"] for h in r["history"]]
    ax.plot(steps, [h["train_loss"] for h in r["history"]], label=f"{r['name']} train")
    val = [(h["step"], h["val_loss"]) for h in r["history"] if "val_loss" in h]
    if val:
      ax.plot(*zip(*val), "--", label=f"{r['name']} val")
  ax.set_xlabel("step")
  ax.set_ylabel("loss (NLL per frame or MSE; GAN runs not drawn)")
  if ax.get_legend_handles_labels()[0]:
    ax.legend(fontsize=7)
  fig.tight_layout()
  save_figure(fig, path)


def _movement_plot(plt, groups, path: Path) -> None:
  fig, ax = plt.subplots(figsize=(8, 4))
  for g in groups:
    curves = [r["eval"]["movement_curve"] for r in g["runs"]]
    n, seg = min(len(c) for c in curves), g["runs"][0]["eval"]["segment_frames"]
    mean, sd = np.mean([c[:n] for c in curves], 0), np.std([c[:n] for c in curves], 0)
    x = np.arange(n) * seg + seg / 2
    ax.plot(x, mean, "o-", label=f"{g['name']} ({len(curves)} runs)")
    ax.fill_between(x, mean - sd, mean + sd, alpha=0.15)
  ax.axhline(1.0, color="k", lw=0.8, ls=":")
  ax.axhspan(0.6, 1.4, color="g", alpha=0.08)
  ax.set_xlabel("generated frame (centre of each segment)")
  ax.set_ylabel("movement over 0.5 s / data's")
  ax.legend(fontsize=7)
  fig.tight_layout()
  save_figure(fig, path)


def _cell(g, key, rule) -> str:
  values = [
    _value(r["eval"], key, rule) for r in g["runs"] if all(r["eval"].get(k) is not None for k in _needs(key, rule))
  ]
  if not values:
    return "-"
  mean, sd = _stats(values)
  return f"{mean:.3g} ± {sd:.2g}" if len(values) > 1 else f"{mean:.4g}"


def _settings(e: dict) -> str:
  """One run's evaluation settings, as the report states them."""
  sampling = ", ".join(f"{k} {v}" for k, v in e["sampling"].items() if k not in ("seed", "seeds"))
  return (
    f"{e['num']} x {e['frames']} frames per sampling seed {e['sampling'].get('seeds')}, compared with "
    f"{', '.join(e['data'])}; segments of {e['segment_frames']} frames; windows of {e['window']} frames for "
    f"FID, Div and novelty; FID_real over {e['splits']} random halves of the reference; sampling: {sampling}"
  )


def _table(groups) -> list[str]:
  settings: dict[str, list[str]] = {}
  for g in groups:
    for r in g["runs"]:
      settings.setdefault(_settings(r["eval"]), []).append(r["name"])
  if len(settings) == 1:
    said = [f"Evaluation of every run: {next(iter(settings))}."]
  else:
    said = ["Evaluation settings differ between runs:"] + [f"- {', '.join(n)}: {s}." for s, n in settings.items()]
  lines = [
    *said,
    "",
    "Cells: mean ± sd over the training seeds of a row (runs whose configs differ only in train.seed and whose names "
    "only in seed=N).",
    "",
    "| config | runs | cell | head | " + " | ".join(c[1] for c in COLUMNS) + " |",
    "|---" * (4 + len(COLUMNS)) + "|",
  ]
  for g in groups:
    c = g["runs"][0]["config"]
    cells = [_cell(g, k, rule) for k, _, rule in COLUMNS]
    loss = [k for k, _, _ in COLUMNS].index("heldout_loss")
    if any(_loss_takes(r["eval"]) == "all" for r in g["runs"]) and cells[loss] != "-":
      cells[loss] += " (incl. training takes)"  # measured on every --data take, none held out
    cell, head = family_of(c).columns(c)
    lines.append(f"| {g['name']} | {len(g['runs'])} | {cell} | {head} | " + " | ".join(cells) + " |")
  e0 = groups[0]["runs"][0]["eval"]
  real = lambda k: f"{mean_of(e0[k]):.4g}" if e0.get(k) is not None else "-"
  reference = {"heldout_loss": "", "bone_cv_mean": "-", "root_step_max": "<= 1"}
  cells = [
    reference.get(k)
    if k in reference
    else f"1 ({real(f'{k}_{rule}')})"
    if rule in ("real", "train")
    else real(rule.split(":")[1])
    if rule.startswith("data:")
    else "1"
    for k, _, rule in COLUMNS
  ]
  lines.append("| real data (reference) | | | | " + " | ".join(str(c) for c in cells) + " |")
  return lines


def _strips(groups, stem: Path) -> list[str]:
  """Each group's first run's evaluation sample as a filmstrip (start, middle, end)."""
  lines = []
  for i, g in enumerate(groups):
    npz = sample_path(metrics_path(g["runs"][0]["dir"]))
    if npz.exists():
      png = Path(f"{stem}_strip{i}.png")
      plot_strip(read_npz(npz)[0].replace(name=f"{g['runs'][0]['name']}: evaluation sample"), png)
      lines += [f"### {g['name']}", "", f"![{g['name']}]({png.name})", ""]
  return lines


def dataset_of(group: dict) -> str:
  """The dataset a group's runs trained on (their ``data.dataset``)."""
  return str(group["runs"][0]["config"].get("data", {}).get("dataset", "?"))


def _wins(groups) -> list[str]:
  """The report's "who wins" lines for ``groups`` (one dataset's)."""
  lines = []
  for key, label, rule in COLUMNS:
    g, why = _winner(groups, key, rule)
    lines.append(f"- **{label}**: " + (f"{g['name']} ({_cell(g, key, rule)}; {why})" if g else why or "-"))
  return lines + _chosen(groups)


def _chosen(groups) -> list[str]:
  """The run one would keep without looking at the held-out takes: of the calibrated runs (two at least),
  the one whose calibrated draws came nearest its own training takes (the lowest calibration objective;
  how well that chooses: ``docs/perf-notes.md``)."""
  calibrated = [
    (r["calibration"], r["name"], g["name"]) for g in groups for r in g["runs"] if r["calibration"] is not None
  ]
  if len(calibrated) < 2:
    return []
  objective, run, group = min(calibrated)
  return [
    f"- **Chosen from the training takes alone**: {run} ({group}), the lowest calibration objective of "
    f"{len(calibrated)} calibrated runs ({objective:.2f}; calibration.json: its draws' distance from its "
    "training takes, no held-out take involved)"
  ]


def _by_dataset(groups) -> list[str]:
  """The table and winners: once, or per dataset where the runs trained on several (a winner on one
  dancer says nothing about another)."""
  datasets: dict[str, list] = {}
  for g in groups:
    datasets.setdefault(dataset_of(g), []).append(g)
  legend = (
    "A winner is named only where its mean beats the next best by more than both spreads (mean ± sd over "
    "training seeds); otherwise: within noise."
  )
  if len(datasets) == 1:
    return [*_table(groups), "", *_NOTES, "", "## Who wins", "", legend, "", *_wins(groups)]
  lines = [f"Runs on {len(datasets)} datasets: each has its own table and winners.", "", *_NOTES, "", legend]
  for name, own in datasets.items():
    lines += ["", f"## Dataset: {name}", "", *_table(own), "", "### Who wins", "", *_wins(own)]
  return lines


_NOTES = [
  "The held-out loss is measured on the evaluation takes a run did not train on (on all of them, marked "
  "'incl. training takes', where none was held out or the run was evaluated before this rule). "
  "Lower is better for held-out loss (NLL and MSE are not comparable) and bone CV; movement and jitter "
  "should be near 1 (movement 0 = trembling in place or frozen); FID / real near 1 or below (the real "
  "data's own halves differ by 1); FID / train takes' near 1 or below (the run's own training takes, scored "
  "as a sample against the held-out takes, differ by 1; '-' where the evaluation has no held-out takes); "
  "speed and root travel near 1; foot sliding, PFC, Div_k and novelty near the real data's (novelty "
  "0 = copying the training data)."
]


def compare(workdirs, output) -> Path:
  """Writes ``report.md``: a table of mean ± sd over training seeds, who wins beyond the spread (both per
  dataset where the runs trained on several), loss and movement plots, and each configuration's evaluation
  sample as filmstrips."""
  runs = [_read_run(Path(w)) for w in workdirs]
  groups = group_runs(runs)
  out = Path(output)
  plt = require_matplotlib()
  stem = out.with_suffix("")
  loss_png, movement_png = Path(f"{stem}_loss.png"), Path(f"{stem}_movement.png")
  _loss_plot(plt, runs, loss_png)
  _movement_plot(plt, groups, movement_png)
  lines = [
    f"# Comparison: {', '.join(g['name'] for g in groups)}",
    "",
    f"Generated by `chorjax compare` on {datetime.date.today()}; {machine_info()}.",
    "",
    *_by_dataset(groups),
  ]
  lines += ["", f"![loss curves]({loss_png.name})", "", f"![movement over time]({movement_png.name})", ""]
  lines += ["## What the models dance", "", *_strips(groups, stem)]
  atomic_write(out, lambda p: p.write_text("\n".join(lines)))
  return out


def compare_to(workdirs, output, *, force: bool = False) -> Path:
  """``chorjax compare``: :func:`compare`, the report and the images written beside it refused where they
  exist (unless ``force``)."""
  stem = Path(output).with_suffix("")
  images = sorted(stem.parent.glob(f"{stem.name}_loss.png")) + sorted(stem.parent.glob(f"{stem.name}_movement.png"))
  images += sorted(stem.parent.glob(f"{stem.name}_strip*.png"))
  refuse_existing([output, *images], force)  # the report's images are written beside it
  return compare(workdirs, output)
