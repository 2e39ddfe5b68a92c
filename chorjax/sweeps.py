"""Sweeps over config keys and comparison reports: experiments that say which model dances better.

A sweep file (TOML)::

    name = "mdn_vs_mse"
    base = "../../configs/quickstart.toml"    # relative to the sweep file
    root = "runs/mdn_vs_mse"                  # where the point workdirs go (relative to the cwd)
    [grid]                                    # the cross product of these lists
    "model.head" = ["mdn", "mse"]
    "train.seed" = [0, 1, 2]                  # training seeds: compare reports mean +- sd over them
    [set]                                     # fixed overrides for every point (optional)
    "train.num_steps" = 2000
    [eval]                                    # what `chorjax eval` measures after training (optional)
    data = ["cmu94/94_10_skeleton_3d.csv"]
    frames = 10000
    num = 1
    seeds = [0, 1, 2, 3]                      # sampling seeds, scored together

Named ``[candidates.NAME]`` tables (config overrides each) are crossed with the grid, so a comparison
of different recipes is one file::

    [candidates.quickstart]
    [candidates.auto_conditioning]
    "train.feedback" = "auto"
    [grid]
    "train.seed" = [0, 1, 2]

``vectorize = ["train.seed", "optim.lr", "train.input_noise"]`` (any of them) trains the points that
differ only in those keys as one vectorized program (``chorjax.points``): one run's cost for
several seeds on a CPU whose cores one small model leaves idle.

Every point is an ordinary run directory (``<root>/<name>-<key>=<value>...``) with its evaluation in
``eval/metrics.json`` (and its first sample in ``eval/sample.npz``); re-running a sweep skips finished
points and resumes unfinished ones. ``chorjax compare`` groups points that differ only in
``train.seed`` (and ``seed=N`` in their names).
"""

from __future__ import annotations

import contextlib
import datetime
import itertools
import json
import platform
import re
import tomllib
from pathlib import Path

import numpy as np

from chorjax.config import check_training_size, load_config, plain_name, suggest, valid_keys
from chorjax.errors import UserError, atomic_write, load_json, load_toml, read_text
from chorjax.families import family_of
from chorjax.runtime import cpu_info
from chorjax.sampling.controls import Controls
from chorjax.scoring import mean_of, upgrade

SWEEP_KEYS = {"name", "base", "root", "grid", "set", "eval", "candidates", "vectorize"}
EVAL_KEYS = {"data", "frames", "num", "seed", "seeds", "splits", "window", *Controls.names()}


# What `chorjax sweep --help` says of a sweep and its file.
SWEEP_DESCRIPTION = (
  "Trains and evaluates every point of a grid over config keys; finished points are skipped,\n"
  "so an interrupted sweep continues where it stopped (docs/guides/sweeps.md)."
)
SWEEP_FORMAT = """The sweep file (TOML):
  name = "lr_sweep"                      # run directories are named NAME-KEY=VALUE-...
  base = "../configs/quickstart.toml"    # the config every point starts from (relative to this file)
  root = "runs/lr_sweep"                 # where the run directories go (relative to the working directory)
  vectorize = ["train.seed"]             # points differing only in these train as one program (optional;
                                         # train.seed, optim.lr, train.input_noise)
  [set]                                  # keys set for every point (optional)
  "train.num_steps" = 1000
  [grid]                                 # every combination of these values is one point
  "optim.lr" = [1e-3, 3e-3]
  "train.seed" = [0, 1, 2]
  [candidates.canonical]                 # named variants, each crossed with the grid (optional)
  "data.representation" = "canonical"
  [eval]                                 # chorjax eval after training (optional): data, frames,
  data = ["cmu94"]                       # num, seed, seeds, splits, window and the sampling
  seeds = [0, 1, 2, 3]                   # controls (pi_temperature, noise_smoothing, ...)

Split over N cluster jobs: chorjax sweep FILE --shard I/N (job I of 0..N-1 runs points I, I+N, ...).
Then: chorjax compare ROOT/* -o report.md"""


def _fmt(v) -> str:
  return json.dumps(v) if isinstance(v, str) else ("true" if v is True else "false" if v is False else repr(v))


def load_sweep(path) -> dict:
  path = Path(path)
  try:
    sweep = load_toml(read_text(path, "sweep"))
  except FileNotFoundError:
    raise UserError(f"{path}: no such sweep file") from None
  except tomllib.TOMLDecodeError as e:
    raise UserError(f"{path}: invalid TOML: {e}") from None
  unknown = set(sweep) - SWEEP_KEYS
  if unknown:
    first = sorted(unknown)[0]
    hint = suggest(first, sorted(SWEEP_KEYS)) or f"; a sweep has {', '.join(sorted(SWEEP_KEYS))}"
    raise UserError(f"{path}: unknown key {first!r}{hint}")
  if not sweep.get("grid"):
    raise UserError(f"{path}: needs a [grid] table of KEY = [values]")
  for key, values in sweep["grid"].items():
    if key not in valid_keys():
      raise UserError(f"{path}: [grid] key {key!r} is not a config key{suggest(key, valid_keys())}")
    if not isinstance(values, list) or not values:
      raise UserError(f"{path}: [grid] {key!r} must be a non-empty list")
  for name, body in sweep.get("candidates", {}).items():
    if not isinstance(body, dict):
      raise UserError(f"{path}: [candidates.{name}] must be a table of KEY = value")
    for key in body:
      if key not in valid_keys():
        raise UserError(f"{path}: [candidates.{name}] key {key!r} is not a config key{suggest(key, valid_keys())}")
  from chorjax.points import VECTOR_KEYS

  vec = sweep.get("vectorize", [])
  if not isinstance(vec, list) or any(k not in VECTOR_KEYS for k in vec):
    wrong = next((k for k in vec if k not in VECTOR_KEYS), vec) if isinstance(vec, list) else vec
    raise UserError(
      f"{path}: vectorize: cannot vectorize {wrong!r}; a list of {', '.join(VECTOR_KEYS)} "
      "(keys that change shapes or the data train apart)"
    )
  bad = set(sweep.get("eval", {})) - EVAL_KEYS
  if bad:
    raise UserError(f"{path}: unknown [eval] key {sorted(bad)[0]!r}; one of {', '.join(sorted(EVAL_KEYS))}")
  sweep.setdefault("name", path.stem)
  sweep["base"] = str((path.parent / sweep["base"]).resolve()) if "base" in sweep else None
  sweep.setdefault("root", f"runs/{sweep['name']}")
  return sweep


def sweep_points(sweep: dict) -> list[tuple[str, list[str]]]:
  """``(point name, overrides)`` for every candidate (``[candidates.NAME]`` tables; one unnamed if none)
  crossed with every grid point."""
  keys = list(sweep["grid"])
  fixed = [f"{k}={_fmt(v)}" for k, v in sweep.get("set", {}).items()]
  candidates = sweep.get("candidates") or {"": {}}
  points = []
  for cand, body in candidates.items():
    own = [f"{k}={_fmt(v)}" for k, v in body.items()]
    for values in itertools.product(*(sweep["grid"][k] for k in keys)):
      tag = "-".join([cand] * bool(cand) + [f"{k.split('.')[-1]}={v}" for k, v in zip(keys, values)])
      name = plain_name(f"{sweep['name']}-{tag}", "sweep point")  # grid values name folders: no / or ..
      points.append((name, fixed + own + [f"{k}={_fmt(v)}" for k, v in zip(keys, values)]))
  return points


def is_finished(workdir: Path, num_steps: int, with_eval: bool) -> bool:
  """Whether a point's run trained to its end (and was evaluated, ``with_eval``): a checkpoint of its last
  step, that step read from the run's own config where ``train.epochs`` resolved it, or the end-of-run sample
  that a finished run writes (also where ``train.patience`` ended it early)."""
  from chorjax import checkpoint as ckpt
  from chorjax.evaluate import metrics_path

  with contextlib.suppress(OSError, ValueError, KeyError, TypeError):
    num_steps = json.loads((Path(workdir) / "config.json").read_text())["train"]["num_steps"]
  samples = Path(workdir) / "samples"
  done = (ckpt.checkpoint_dir(workdir) / str(num_steps)).is_dir() or (samples.is_dir() and any(samples.iterdir()))
  return done and (not with_eval or metrics_path(workdir).exists())


def sweep_groups(sweep: dict) -> list[list[tuple[str, list[str]]]]:
  """The points of :func:`sweep_points` grouped for training: points that differ only in the sweep's
  ``vectorize`` keys form one group (trained as one vectorized program); without it, one point each."""
  vec = set(sweep.get("vectorize", []))
  groups: dict[tuple, list] = {}
  for name, overrides in sweep_points(sweep):
    key = tuple(o for o in overrides if o.split("=", 1)[0] not in vec)
    groups.setdefault(key, []).append((name, overrides))
  return list(groups.values())


def run_sweep(path, log=print, shard: tuple[int, int] = (0, 1)) -> list[Path]:
  """Trains (and evaluates) every point of a sweep; returns the point workdirs.

  Points that differ only in the ``vectorize`` keys train together (``chorjax.points``); points
  whose checkpoints are at different steps fall back to training one by one. ``shard = (i, n)``: only
  the groups (points, without ``vectorize``) whose index is ``i`` modulo ``n`` (0-based ``i``), so ``n``
  jobs with no coordinator split a sweep (a job array), each skipping what is already finished;
  ``compare`` over the shared root merges them."""
  from chorjax import checkpoint as ckpt
  from chorjax.evaluate import evaluate, metrics_path, write_metrics

  sweep = load_sweep(path)
  ev = sweep.get("eval")
  workdirs = []
  index, count = shard
  for k, group in enumerate(sweep_groups(sweep)):
    if k % count != index:
      continue
    points = [(n, o, load_config(sweep["base"], [*o, f"name={_fmt(n)}"]), Path(sweep["root"]) / n) for n, o in group]
    workdirs += [w for *_, w in points]
    todo = [p for p in points if not is_finished(p[3], p[2].train.num_steps, bool(ev))]
    for name, *_ in (p for p in points if p not in todo):
      log(f"{name}: finished, skipped")
    train = [p for p in todo if not (ckpt.checkpoint_dir(p[3]) / str(p[2].train.num_steps)).is_dir()]
    _train_points(train, log)
    for name, _, cfg, workdir in todo:
      if ev:
        log(f"{name}: evaluating")
        kw = {k: v for k, v in ev.items() if k != "data"}
        write_metrics(evaluate(workdir, ev.get("data", [cfg.data.dataset]), **kw), metrics_path(workdir))
    _release_compiled()
  return workdirs


def _release_compiled() -> None:
  """Drops the programs a point compiled. A sweep is one process: every point's training, calibration (~30
  programs) and evaluation compile anew, and each compiled program holds its own memory mappings, so after
  about ten points the kernel's limit on a process's mappings (vm.max_map_count, 65,530) was reached and
  LLVM failed ("Unable to allocate section memory") with most of the memory free."""
  import gc

  import jax

  jax.clear_caches()
  gc.collect()


def _train_points(points, log) -> None:
  """Trains ``(name, overrides, cfg, workdir)`` points: together when there are several, else alone."""
  from chorjax.end_of_run import standard
  from chorjax.points import NotAligned
  from chorjax.training import train_and_evaluate
  from chorjax.vectorized import train_vectorized

  if len(points) > 1:
    log(f"{', '.join(n for n, *_ in points)}: training together ({' '.join(points[0][1])} ...)")
    try:
      train_vectorized([c for _, _, c, _ in points], [w for *_, w in points])
      return
    except NotAligned as e:
      log(f"{e}: one by one")
  for name, overrides, cfg, workdir in points:
    log(f"{name}: training ({' '.join(overrides)})")
    train_and_evaluate(cfg, workdir, finish=standard(cfg))


# ---------------------------------------------------------------- comparison report

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


def machine_info() -> str:
  """CPU model, core count and library versions, for reports and benchmarks."""
  import os

  import jax

  cpu = cpu_info().get("model name") or platform.processor() or platform.machine()
  return (
    f"{cpu}, {os.cpu_count()} cores, {jax.devices()[0].platform}; Python {platform.python_version()}, "
    f"jax {jax.__version__}"
  )


def _read_run(workdir: Path) -> dict:
  from chorjax.evaluate import metrics_path

  cfg_path, ev_path = workdir / "config.json", metrics_path(workdir)
  if not cfg_path.exists():
    raise UserError(f"{workdir}: not a run directory (no config.json)")
  if not ev_path.exists():
    raise UserError(f"{ev_path}: missing; run `chorjax eval {workdir} --data ...` first")
  from chorjax.training import metrics_row

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
  from chorjax.sampling.calibration_file import chosen_calibration_row

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
  from chorjax.render.plot import save_figure

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
  from chorjax.render.plot import save_figure

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
  from chorjax.data.npz import read_npz
  from chorjax.evaluate import metrics_path, sample_path
  from chorjax.render.plot import plot_strip

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
  the one whose calibrated draws came nearest its own training takes (the lowest calibration objective).
  On the dancers benchmark this picked, among 3 cells x 3 seeds, the best held-out FID_g on salsa and a
  good one on cmu94, not on martial (experiments/across_datasets/table.md)."""
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
  from chorjax.render.plot import require_matplotlib

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
  from chorjax.errors import refuse_existing

  stem = Path(output).with_suffix("")
  images = sorted(stem.parent.glob(f"{stem.name}_loss.png")) + sorted(stem.parent.glob(f"{stem.name}_movement.png"))
  images += sorted(stem.parent.glob(f"{stem.name}_strip*.png"))
  refuse_existing([output, *images], force)  # the report's images are written beside it
  return compare(workdirs, output)


def train_command(config, overrides=(), *, workdir=None, force: bool = False, log=print) -> list[dict]:
  """``chorjax train``: ``config`` (a TOML path) with ``overrides``; a list for a vectorizable key
  (``train.seed=[0,1,2]``) trains one run directory a point (``WORKDIR/seed=0`` ...) as one program, else
  one run (data-parallel over processes where ``[parallel]`` says). ``log`` hears a line a run trained.
  Returns the runs' summaries (:func:`train_and_evaluate`)."""
  from chorjax import end_of_run
  from chorjax.parallel import setup_parallel
  from chorjax.points import expand_overrides
  from chorjax.training import default_workdir, train_and_evaluate
  from chorjax.vectorized import train_vectorized

  overrides, points = expand_overrides(list(overrides))
  if len(points) == 1:  # a one-element list is that value, checked as the value alone is
    overrides += [f"{k}={v!r}" for k, v in points[0]]
  cfg = load_config(config, overrides)
  workdir = Path(workdir) if workdir else default_workdir(cfg)
  if len(points) > 1:
    check_training_size(cfg, copies=len(points))  # before K configs are even built
    tag = lambda p: "-".join(f"{k.split('.')[-1]}={v}" for k, v in p)
    cfgs = [load_config(config, [*overrides, *(f"{k}={v!r}" for k, v in p)]) for p in points]
    dirs = [workdir / tag(p) for p in points]
    summaries = train_vectorized(cfgs, dirs, force=force)
    for d, s in zip(dirs, summaries):
      log(f"trained {d.name}: steps {s['start_step']}->{s['final_step']}{_losses(s)}; workdir {d}")
    return summaries
  parallel = setup_parallel(cfg)
  s = train_and_evaluate(cfg, workdir, force=force, parallel=parallel, finish=end_of_run.standard(cfg))
  if parallel is not None and not parallel.is_main:
    log(
      f"process {parallel.process_index}/{parallel.process_count}: steps {s['start_step']}->"
      f"{s['final_step']}, final train loss {s.get('final_train_loss', float('nan')):.6g}"
    )
    return [s]
  steps = f"steps {s['start_step']}->{s['final_step']}"
  log(f"trained {Path(workdir).resolve().name}: {steps}{_losses(s)}, {s['seconds']:.0f} s; workdir {workdir}")
  if "samples" in s:
    log(f"sample: {s['samples']['csv']}\nwatch it: {s['samples']['html']}")
  return [s]


def _losses(summary: dict) -> str:
  """``, train loss X, val loss Y`` of a run's summary (what it has of them)."""
  train = f", train loss {summary['final_train_loss']:.4g}" if "final_train_loss" in summary else ""
  val = f", val loss {summary['final_val_loss']:.4g}" if "final_val_loss" in summary else ""
  if "kept_step" in summary:  # train.keep = "best": the checkpoint sample, eval and export use
    val += f"; kept: step {summary['kept_step']} (val loss {summary['kept_val_loss']:.4g})"
  return train + val
