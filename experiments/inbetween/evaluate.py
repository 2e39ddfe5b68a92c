"""The in-betweening evaluation: LaFAN1's protocol adapted to chorjax's held-out dance.

Transitions of 5, 15, 30 and 45 frames after 10 context frames, in windows every 40 frames of held-out
takes: cmu94's validation take (94_10) and the CMU dance takes in ../shared/data (subject 5, modern dance,
and subject 131, Michael-Jackson-style; ASF/AMC at 120 fps), converted as the runs read their data (mapped
onto the 16 joints, cmu94's axes, 30 fps), scaled to cmu94's body (the same leg length) and set on its
floor (cmu94's floor lies 4 leg lengths below its y origin, the ASF takes' at it; the models read heights). Methods: the
zero-velocity and linear-interpolation baselines and every trained run given (several training seeds of
one config make one row: mean +- sd). Run from the repository root after training, e.g.:

  .venv/bin/python experiments/inbetween/evaluate.py runs/inbetween/inbetween-seed*

Writes experiments/inbetween/report.md, results.json and strip_30.png (a 30-frame transition from each).
"""

import argparse
import json
import re
import sys
from pathlib import Path

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # benchmarks/, beside chorjax/
from benchmarks import lafan1
from chorjax.compare import machine_info
from chorjax.data.dataset import conform, load_dataset, read_takes, to_rate
from chorjax.data.features import leg_length
from chorjax.families.inbetween import inbetweening as ib
from chorjax.run import load_run

HERE = Path(__file__).parent
BASELINES = ("zero velocity", "linear interpolation", "nearest 20 training transitions")
OTHERS = ("../shared/data/asfamc/cmu05", "../shared/data/asfamc/cmu131")
METRICS = (
  ("l2p", "L2P", 2),
  ("position_error", "position error (leg lengths)", 3),
  ("npss", "NPSS", 4),
  ("foot_skate", "foot skate (leg lengths / frame)", 4),
  ("arrival_step", "step into the target / the data's step", 2),
)


def held_out(run) -> dict[str, list[np.ndarray]]:
  """Canonical positions of the held-out takes, by set: the run's validation takes (cmu94's 94_10 for
  configs/inbetween.toml), then the other dancers."""
  ds = load_dataset(run.config.data)
  sets = {f"{Path(run.config.data.dataset).name} " + ", ".join(ds.val_names): ib.held_out_takes(ds)}
  size, f = ib.Space.of(run.features).size, run.features
  feet = list(f.skeleton.feet)
  floor = lambda takes: np.percentile(np.concatenate([t[:, feet, 1] for t in takes]), 5)
  train_floor = floor(ib.training_takes(ds, ()))
  for folder in OTHERS:
    if not Path(folder).is_dir():
      print(f"warning: {folder} not found: evaluated without it", file=sys.stderr)
      continue
    takes = [to_rate(m, ds.fps) for m in conform(read_takes([folder], run.config.data), run.config.data)]
    canon = [np.asarray(f.canonical(m.positions), np.float32) for m in takes]
    canon = [c * (size / leg_length(c, f.skeleton)) for c in canon]  # the run's body size
    lift = np.array([0.0, train_floor - floor(canon), 0.0], np.float32)  # on its training floor
    sets[Path(folder).name] = [c + lift for c in canon]
  return sets


def nearest_transitions(train_takes, space: ib.Space, context: int, k: int = 20):
  """A non-learned baseline: the mean of the ``k`` training transitions (windows every 2 frames, with
  mirror images and the takes played backwards) whose last 3 context frames and target are nearest, each
  bent to start at this context's last frame and end at this target (the endpoint errors interpolated)."""
  cache: dict = {}

  def key_of(ctx, target):
    return np.concatenate([3.0 * ctx[:, -3:].reshape(len(ctx), -1), target], -1)

  def fn(ctx, target, n):
    if n not in cache:
      wins, _ = lafan1.benchmark_windows(train_takes, context, n, hop=2)
      local = ib.local_windows(space, wins, context)
      cache[n] = (local, key_of(local[:, :context], local[:, context + n]))
    local, keys = cache[n]
    query = key_of(ctx, target)
    dist = (query**2).sum(-1)[:, None] - 2 * query @ keys.T + (keys**2).sum(-1)[None]
    near = np.argsort(dist, 1)[:, :k]
    alpha = (np.arange(1, n + 1) / (n + 1))[None, None, :, None]
    w = local[near]  # [B, k, W, K]
    start = ctx[:, None, -1:] - w[:, :, context - 1 : context]
    end = target[:, None, None] - w[:, :, context + n : context + n + 1]
    return (w[:, :, context : context + n] + (1 - alpha) * start + alpha * end).mean(1)

  return fn


def methods_of(runs, nearest=None) -> dict:
  out = {"zero velocity": lafan1.zero_velocity, "linear interpolation": lafan1.linear}
  if nearest is not None:
    out["nearest 20 training transitions"] = nearest
  for r in runs:
    key = jax.random.key(0)
    out[str(r.workdir)] = lambda c, t, n, r=r, key=key: ib.model_transitions(
      r.graphdef, r.params, r.config.inbetween, c, t, n, jax.random.fold_in(key, n)
    )
  return out


def groups_of(runs) -> dict[str, list[str]]:
  """Row label -> the methods pooled in it (the trained runs of one config: its training seeds)."""
  groups = {m: [m] for m in BASELINES}
  for r in runs:
    config = re.sub(r"-seed=\d+$", "", r.config.name)  # a sweep names each point CONFIG-seed=N
    groups.setdefault(f"{config} ({r.config.inbetween.system})", []).append(str(r.workdir))
  return groups


def cell(results: dict, members, n: int, key: str, digits: int, over_linear: bool = False) -> str:
  """``mean ± sd`` over ``members`` (a value alone for one), optionally as a ratio to linear interpolation's."""
  base = results["linear interpolation"][n][key] if over_linear else 1.0
  v = np.array([results[m][n][key] / base for m in members])
  return f"{v.mean():.{digits}f}" + (f" ± {v.std(ddof=1):.{digits}f}" if len(v) > 1 else "")


def label(name: str, members) -> str:
  return f"{name} ({len(members)} training seeds)" if len(members) > 1 else name


def table(results: dict, groups: dict, lengths) -> list[str]:
  """Markdown tables, one per metric, a row per method, a column per transition length; then the position
  errors and L2P as ratios to linear interpolation's (the acceptance's terms)."""
  lines = []
  rows = [(k, t, d, False) for k, t, d in METRICS]
  rows += [("position_error", "position error / linear interpolation's", 3, True)]
  rows += [("l2p", "L2P / linear interpolation's", 3, True)]
  for key, title, digits, ratio in rows:
    lines += [f"\n**{title}**\n", "| method | " + " | ".join(f"{n} frames" for n in lengths) + " |"]
    lines.append("|---" * (len(lengths) + 1) + "|")
    for name, members in groups.items():
      cells = [cell(results, members, n, key, digits, ratio) for n in lengths]
      lines.append(f"| {label(name, members)} | " + " | ".join(cells) + " |")
  return lines


def set_table(per_set: dict, groups: dict) -> list[str]:
  lines = [
    "**By held-out set**: position error / linear interpolation's (and L2P) at 5 and 30 frames",
    "",
    "| set | method | 5 frames | 30 frames | L2P, 5 | L2P, 30 |",
    "|---|---|---|---|---|---|",
  ]
  for name, res in per_set.items():
    for g, members in groups.items():
      ratios = [cell(res, members, n, "position_error", 3, True) for n in (5, 30)]
      l2ps = [cell(res, members, n, "l2p", 2) for n in (5, 30)]
      lines.append(f"| {name} | {label(g, members)} | " + " | ".join(ratios + l2ps) + " |")
  return lines


def strip(runs, take, path: Path, context: int = 10, frames: int = 30, start: int = 200) -> None:
  """A 30-frame transition after frame ``start`` of ``take`` from each method (each config's first run),
  every 3rd frame, beside the real one."""
  import matplotlib

  matplotlib.use("Agg")
  import matplotlib.pyplot as plt

  from chorjax.render.plot import draw_strip

  first = runs[0]
  space = ib.Space.of(first.features)
  start = min(start, len(take) - (context + frames + 1))
  local = ib.local_windows(space, take[None, start : start + context + frames + 1], context)
  ctx, target = local[:, :context], local[:, context + frames]
  rows = {
    "real": local[0, context - 1 : context + frames + 1],
    "zero velocity": lafan1.zero_velocity(ctx, target, frames)[0],
    "linear interpolation": lafan1.linear(ctx, target, frames)[0],
  }
  for name, members in groups_of(runs).items():
    run = next((r for r in runs if str(r.workdir) == members[0]), None)
    if run is not None:
      ib_cfg = run.config.inbetween
      rows[name] = ib.model_transitions(run.graphdef, run.params, ib_cfg, ctx, target, frames, jax.random.key(0))[0]
  fig, axes = plt.subplots(len(rows), 1, figsize=(13, 1.9 * len(rows)), squeeze=False)
  for ax, (name, seq) in zip(axes[:, 0], rows.items()):
    if len(seq) == frames:  # the written frames: add the last context frame and the target around them
      seq = np.concatenate([local[0, context - 1 : context], seq, target], 0)
    pos = space.from_local(seq, (0.0, np.zeros(3, np.float32)))
    draw_strip(ax, pos, first.features.skeleton, list(range(0, frames + 2, 3)) + [frames + 1], spacing=1.1 * space.size)
    ax.set_title(
      f"{name}: last context frame (0), every 3rd written frame, the target ({frames + 1})", fontsize=8, loc="left"
    )
  fig.tight_layout()
  fig.savefig(path, dpi=110)
  plt.close(fig)


def main() -> None:
  parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
  parser.add_argument("runs", nargs="+", help="trained in-betweening run directories")
  parser.add_argument("--out", default=str(HERE), help="folder for report.md, results.json, strip_30.png")
  args = parser.parse_args()
  runs = [load_run(w) for w in args.runs]
  first = runs[0]
  context = first.config.inbetween.context
  space = ib.Space.of(first.features)
  ds = load_dataset(first.config.data)
  std = lafan1.window_std(ib.training_takes(ds, ()), space, context)
  methods = methods_of(runs, nearest_transitions(ib.training_takes(ds, ("mirror", "reverse")), space, context))
  sets = held_out(first)
  takes = [t for ts in sets.values() for t in ts]
  feet = first.features.skeleton.feet
  results = lafan1.benchmark(methods, takes, space, feet, context, std)
  per_set = {
    name: lafan1.benchmark(methods, ts, space, feet, context, std, lengths=(5, 30)) for name, ts in sets.items()
  }
  out = Path(args.out)
  out.mkdir(parents=True, exist_ok=True)
  (out / "results.json").write_text(json.dumps({"all": results, "by_set": per_set}, indent=1, default=float))
  strip(runs, takes[0], out / "strip_30.png", context)
  windows = len(lafan1.benchmark_windows(takes, context, max(lafan1.BENCHMARK_LENGTHS))[0])
  lines = [
    "# In-betweening: held-out transitions",
    "",
    f"{windows} windows every 40 frames of {len(takes)} held-out takes ({', '.join(sets)}); {context} context "
    "frames; L2P as LaFAN1 (local positions / the training windows' per-coordinate std).",
    f"Machine: {machine_info()}.",
    *table(results, groups_of(runs), lafan1.BENCHMARK_LENGTHS),
    "",
    *set_table(per_set, groups_of(runs)),
  ]
  lines += ["", f"![a 30-frame transition of {next(iter(sets))}, from frame 200](strip_30.png)", ""]
  (out / "report.md").write_text("\n".join(lines))
  print(f"wrote {out / 'report.md'}")


if __name__ == "__main__":
  main()
