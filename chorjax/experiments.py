"""Sweeps over config keys and comparison reports: experiments that say which model dances better.

A sweep file (TOML)::

    name = "mdn_vs_mse"
    base = "../../configs/quickstart.toml"    # relative to the sweep file
    root = "runs/mdn_vs_mse"                  # where the point workdirs go (relative to the cwd)
    [grid]                                    # the cross product of these lists
    "model.head" = ["mdn", "mse"]
    [set]                                     # fixed overrides for every point (optional)
    "train.seed" = 0
    [eval]                                    # what `chorjax eval` measures after training (optional)
    data = ["cmu94/94_10_skeleton_3d.csv"]
    frames = 10000
    num = 4

Every point is an ordinary run directory (``<root>/<name>-<key>=<value>...``) with its evaluation in
``eval/metrics.json``; re-running a sweep skips finished points and resumes unfinished ones.
"""

from __future__ import annotations

import contextlib
import datetime
import itertools
import json
import platform
import tomllib
from pathlib import Path

import numpy as np

from chorjax.config import load_config, valid_keys
from chorjax.errors import UserError, atomic_write
from chorjax.scoring import mean_of

SWEEP_KEYS = {"name", "base", "root", "grid", "set", "eval"}
EVAL_KEYS = {"data", "frames", "num", "seed", "pi_temperature", "sigma_temperature", "greedy"}


def _fmt(v) -> str:
  return json.dumps(v) if isinstance(v, str) else ("true" if v is True else "false" if v is False else repr(v))


def load_sweep(path) -> dict:
  path = Path(path)
  try:
    sweep = tomllib.loads(path.read_text())
  except FileNotFoundError:
    raise UserError(f"{path}: no such sweep file") from None
  except tomllib.TOMLDecodeError as e:
    raise UserError(f"{path}: invalid TOML: {e}") from None
  unknown = set(sweep) - SWEEP_KEYS
  if unknown:
    raise UserError(f"{path}: unknown key {sorted(unknown)[0]!r}; a sweep has {', '.join(sorted(SWEEP_KEYS))}")
  if not sweep.get("grid"):
    raise UserError(f"{path}: needs a [grid] table of KEY = [values]")
  for key, values in sweep["grid"].items():
    if key not in valid_keys():
      raise UserError(f"{path}: [grid] key {key!r} is not a config key")
    if not isinstance(values, list) or not values:
      raise UserError(f"{path}: [grid] {key!r} must be a non-empty list")
  bad = set(sweep.get("eval", {})) - EVAL_KEYS
  if bad:
    raise UserError(f"{path}: unknown [eval] key {sorted(bad)[0]!r}; one of {', '.join(sorted(EVAL_KEYS))}")
  sweep.setdefault("name", path.stem)
  sweep["base"] = str((path.parent / sweep["base"]).resolve()) if "base" in sweep else None
  sweep.setdefault("root", f"runs/{sweep['name']}")
  return sweep


def sweep_points(sweep: dict) -> list[tuple[str, list[str]]]:
  """``(point name, overrides)`` for every grid point."""
  keys = list(sweep["grid"])
  fixed = [f"{k}={_fmt(v)}" for k, v in sweep.get("set", {}).items()]
  points = []
  for values in itertools.product(*(sweep["grid"][k] for k in keys)):
    tag = "-".join(f"{k.split('.')[-1]}={v}" for k, v in zip(keys, values))
    points.append((f"{sweep['name']}-{tag}", fixed + [f"{k}={_fmt(v)}" for k, v in zip(keys, values)]))
  return points


def is_finished(workdir: Path, num_steps: int, with_eval: bool) -> bool:
  from chorjax import checkpoint as ckpt
  from chorjax.evaluate import metrics_path

  done = (ckpt.checkpoint_dir(workdir) / str(num_steps)).is_dir()
  return done and (not with_eval or metrics_path(workdir).exists())


def run_sweep(path, log=print) -> list[Path]:
  """Trains (and evaluates) every point of a sweep; returns the point workdirs."""
  from chorjax.evaluate import evaluate, metrics_path, write_metrics
  from chorjax.train import train_and_evaluate

  sweep = load_sweep(path)
  ev = sweep.get("eval")
  workdirs = []
  for name, overrides in sweep_points(sweep):
    cfg = load_config(sweep["base"], [*overrides, f"name={_fmt(name)}"])
    workdir = Path(sweep["root"]) / name
    workdirs.append(workdir)
    if is_finished(workdir, cfg.train.num_steps, bool(ev)):
      log(f"{name}: finished, skipped")
      continue
    log(f"{name}: training ({' '.join(overrides)})")
    train_and_evaluate(cfg, workdir)
    if ev:
      log(f"{name}: evaluating")
      kw = {k: v for k, v in ev.items() if k != "data"}
      write_metrics(evaluate(workdir, ev.get("data", [cfg.data.dataset]), **kw), metrics_path(workdir))
  return workdirs


# ---------------------------------------------------------------- comparison report

# metric -> (label, how to pick the winner)
COLUMNS = [
  ("heldout_loss", "held-out loss", "min"),
  ("movement_first_1000", "movement first 1k", "one"),
  ("movement_last_1000", "movement last 1k", "one"),
  ("movement_min", "movement min", "one"),
  ("jitter", "jitter", "one"),
  ("bone_cv_mean", "bone CV mean", "min"),
  ("foot_sliding", "foot slide", "data:data_foot_sliding"),
  ("pfc", "PFC", "data:data_pfc"),
  ("fid_k", "FID_k", "min"),
  ("fid_g", "FID_g", "min"),
  ("div_k", "Div_k", "data:div_k_real"),
  ("novelty", "novelty", "data:novelty_real"),
]


def machine_info() -> str:
  """CPU model, core count and library versions, for reports and benchmarks."""
  import os

  import jax

  cpu = platform.processor() or platform.machine()
  with contextlib.suppress(OSError, StopIteration):
    cpu = next(
      l.split(":", 1)[1].strip() for l in Path("/proc/cpuinfo").read_text().splitlines() if l.startswith("model name")
    )
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
  rows = (
    [json.loads(l) for l in (workdir / "metrics.jsonl").read_text().splitlines() if l.strip()]
    if (workdir / "metrics.jsonl").exists()
    else []
  )
  return {
    "name": workdir.name,
    "dir": workdir,
    "config": json.loads(cfg_path.read_text()),
    "eval": json.loads(ev_path.read_text()),
    "history": rows,
  }


def _winner(runs, key, rule):
  vals = [(mean_of(r["eval"][key]), r) for r in runs if r["eval"].get(key) is not None]
  if key == "heldout_loss":  # NLL and MSE are not comparable: only among runs of one kind
    kinds = {r["eval"]["loss_kind"] for _, r in vals}
    if len(kinds) > 1:
      return None, "not comparable (NLL vs MSE)"
  if not vals:
    return None, ""
  if rule == "min":
    _, r = min(vals, key=lambda x: x[0])
    return r, "lowest"
  if rule == "one":
    _, r = min(vals, key=lambda x: abs(x[0] - 1.0))
    return r, "closest to 1 (the data's)"
  ref_key = rule.split(":")[1]
  _, r = min(vals, key=lambda x: abs(x[0] - mean_of(x[1]["eval"][ref_key])))
  return r, "closest to the real data's value"


def _loss_plot(plt, runs, path: Path) -> None:
  from chorjax.render.plot import save_figure

  fig, ax = plt.subplots(figsize=(8, 4))
  for r in runs:
    steps = [h["step"] for h in r["history"]]
    ax.plot(steps, [h["train_loss"] for h in r["history"]], label=f"{r['name']} train")
    val = [(h["step"], h["val_loss"]) for h in r["history"] if "val_loss" in h]
    if val:
      ax.plot(*zip(*val), "--", label=f"{r['name']} val")
  ax.set_xlabel("step")
  ax.set_ylabel("loss (NLL per frame or MSE)")
  ax.legend(fontsize=7)
  fig.tight_layout()
  save_figure(fig, path)


def _movement_plot(plt, runs, path: Path) -> None:
  from chorjax.render.plot import save_figure

  fig, ax = plt.subplots(figsize=(8, 4))
  for r in runs:
    curve = r["eval"]["movement_curve"]
    ax.plot(np.arange(len(curve)) * 1000 + 500, curve, "o-", label=r["name"])
  ax.axhline(1.0, color="k", lw=0.8, ls=":")
  ax.axhspan(0.6, 1.4, color="g", alpha=0.08)
  ax.set_xlabel("generated frame (centre of each 1,000-frame segment)")
  ax.set_ylabel("movement over 0.5 s / data's")
  ax.legend(fontsize=7)
  fig.tight_layout()
  save_figure(fig, path)


def _table(runs) -> list[str]:
  e0 = runs[0]["eval"]
  lines = [
    f"Samples: {e0['num']} x {e0['frames']} frames per run; compared with {', '.join(e0['data'])}; "
    f"windows of {e0['window']} frames for FID, Div and novelty; FID spreads over {e0['splits']} splits.",
    "",
    "| run | cell | head | steps | " + " | ".join(c[1] for c in COLUMNS) + " |",
    "|---" * (4 + len(COLUMNS)) + "|",
  ]
  for r in runs:
    m, c = r["eval"], r["config"]
    cells = [f"{mean_of(m[k]):.4g}" if m.get(k) is not None else "-" for k, _, _ in COLUMNS]
    lines.append(
      f"| {r['name']} | {c['model']['cell']} | {c['model']['head']} | {m['checkpoint_step']} | "
      + " | ".join(cells)
      + " |"
    )
  real = lambda k: f"{mean_of(e0[k]):.4g}" if k in e0 else "-"
  lines.append(
    f"| real data (reference) | | | | | 1 | 1 | 1 | 1 | - | {real('data_foot_sliding')} | {real('data_pfc')} | "
    f"{real('fid_k_real')} (half vs half) | {real('fid_g_real')} (half vs half) | {real('div_k_real')} | "
    f"{real('novelty_real')} |"
  )
  return lines


def compare(workdirs, output) -> Path:
  """Writes ``report.md`` with a metrics table, loss and movement plots, and a summary."""
  from chorjax.render.plot import require_matplotlib

  runs = [_read_run(Path(w)) for w in workdirs]
  out = Path(output)
  plt = require_matplotlib()
  stem = out.with_suffix("")
  loss_png, movement_png = Path(f"{stem}_loss.png"), Path(f"{stem}_movement.png")
  _loss_plot(plt, runs, loss_png)
  _movement_plot(plt, runs, movement_png)
  lines = [
    f"# Comparison: {', '.join(r['name'] for r in runs)}",
    "",
    f"Generated by `chorjax compare` on {datetime.date.today()}; {machine_info()}.",
    "",
    *_table(runs),
    "",
    "Lower is better for held-out loss (NLL and MSE are not comparable), bone CV and FID; movement and "
    "jitter should be near 1 (movement 0 = trembling in place or frozen); foot sliding, PFC, Div_k and "
    "novelty should be near the real data's (novelty 0 = copying the training data).",
    "",
    "## Who wins",
    "",
  ]
  for key, label, rule in COLUMNS:
    r, why = _winner(runs, key, rule)
    lines.append(f"- **{label}**: " + (f"{r['name']} ({mean_of(r['eval'][key]):.4g}; {why})" if r else why or "-"))
  lines += ["", f"![loss curves]({loss_png.name})", "", f"![movement over time]({movement_png.name})", ""]
  atomic_write(out, lambda p: p.write_text("\n".join(lines)))
  return out
