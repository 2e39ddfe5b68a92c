"""Sweeps over config keys: experiments that say which model dances better (their report: ``chorjax.compare``).

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
differ only in those keys as one vectorized program (``chorjax.training.points``): one run's cost for
several seeds on a CPU whose cores one small model leaves idle.

Every point is an ordinary run directory (``<root>/<name>-<key>=<value>...``) with its evaluation in
``eval/metrics.json`` (and its first sample in ``eval/sample.npz``); re-running a sweep skips finished
points and resumes unfinished ones. ``chorjax compare`` groups points that differ only in
``train.seed`` (and ``seed=N`` in their names).
"""

from __future__ import annotations

import contextlib
import gc
import itertools
import json
from pathlib import Path

import jax

from chorjax import checkpoint as ckpt
from chorjax.config import check_training_size, load_config, plain_name, valid_keys
from chorjax.errors import UserError, read_toml
from chorjax.evaluation.evaluate import evaluate, metrics_path, write_metrics
from chorjax.fields import suggest
from chorjax.sampling.controls import Controls
from chorjax.training import end_of_run
from chorjax.training.driver import default_workdir, train_and_evaluate
from chorjax.training.end_of_run import standard
from chorjax.training.parallel import setup_parallel
from chorjax.training.points import VECTOR_KEYS, NotAligned, expand_overrides
from chorjax.training.vectorized import train_vectorized

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
  sweep = read_toml(path, "sweep")
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

  Points that differ only in the ``vectorize`` keys train together (``chorjax.training.points``); points
  whose checkpoints are at different steps fall back to training one by one. ``shard = (i, n)``: only
  the groups (points, without ``vectorize``) whose index is ``i`` modulo ``n`` (0-based ``i``), so ``n``
  jobs with no coordinator split a sweep (a job array), each skipping what is already finished;
  ``compare`` over the shared root merges them."""
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
  jax.clear_caches()
  gc.collect()


def _train_points(points, log) -> None:
  """Trains ``(name, overrides, cfg, workdir)`` points: together when there are several, else alone."""
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


def train_command(config, overrides=(), *, workdir=None, force: bool = False, log=print) -> list[dict]:
  """``chorjax train``: ``config`` (a TOML path) with ``overrides``; a list for a vectorizable key
  (``train.seed=[0,1,2]``) trains one run directory a point (``WORKDIR/seed=0`` ...) as one program, else
  one run (data-parallel over processes where ``[parallel]`` says). ``log`` hears a line a run trained.
  Returns the runs' summaries (:func:`train_and_evaluate`)."""
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
