"""``chorjax eval``: held-out likelihood plus the generation metrics of ``chorjax.evaluation.scoring`` for a run."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import jax
import numpy as np

from chorjax.data.dataset import eval_windows
from chorjax.data.motion import Motion
from chorjax.data.transforms import to_y_up
from chorjax.errors import UserError, atomic_write, check_output, refuse_existing
from chorjax.evaluation import scoring
from chorjax.io.output import write_motions
from chorjax.run import HELD_OUT, Run, load_run, read_reference  # noqa: F401  (re-exported)
from chorjax.runtime import side_by_side
from chorjax.sampling.controls import Controls


def evaluate(
  workdir,
  data: Sequence[str],
  *,
  frames: int = 10_000,
  num: int = 4,
  checkpoint="kept",
  seed: int = 0,
  seeds: Sequence[int] | None = None,
  window: int = 60,
  splits: int = 10,
  **controls,
) -> dict:
  """Samples ``num`` dancers of ``frames`` frames and measures them against the takes in ``data``.

  Args:
    workdir: a run directory.
    data: bundled names, folders or files: the real motion to compare with (e.g. the held-out take).
    frames, num: length and count of generated sequences (dancer k is conditioned on the k-th
      training take, round robin).
    seed, seeds: sampling seed(s); with several, ``num`` dancers are drawn with each and all are
      scored together (every key then carries a mean and sd over them).
    window, splits: windows and reference splits of the distribution metrics (``chorjax.evaluation.scoring``).
    controls: sampling controls (``controls.Controls``: temperatures, greedy, noise smoothing,
      persistence, rigid bones); unset or None: the run's ``[sample]``.

  Returns:
    The loss on the takes of ``data`` the run did not train on (``loss_takes = "held-out"``; on all of them,
    ``"all"``, when it trained on every one; None for a GAN, which has no likelihood) and every key of
    :func:`chorjax.evaluation.scoring.score` (JSON-ready): the generated motion measured against the takes in
    ``data``, novelty against the run's training takes.
  """
  run = load_run(workdir, checkpoint).serving("eval")
  nseeds = len(seeds) if seeds else 1
  run.check_drawn(frames * num * nseeds, f"--frames {frames} x --num {num} x {nseeds} seeds")
  sampling = run.sampling(**controls)
  run = run.ranged(sampling)
  feats = run.features
  sk, fps = feats.skeleton, run.fps
  real, train = read_reference(run, data)
  if frames < 2 * window:
    raise UserError(f"--frames {frames}: need at least {2 * window} frames")

  scored_takes, loss_takes = held_out(real, run.train_takes)
  loss = heldout_loss(run, scored_takes) if run.family.likelihood else None
  seeds = list(seeds) if seeds else [seed]
  decoded = list(side_by_side(lambda s: generate_positions(run, train, num, frames, s, sampling), seeds))
  y_up = lambda pos: np.asarray(to_y_up(pos, feats.up_axis))  # data space -> y-up: what the metrics measure
  gen = [y_up(p) for d in decoded for p in d]
  real_c = [y_up(m.positions) for m in real]
  train_c = [y_up(m.positions) for m in train]

  if sum(len(p) // max(window // 4, 1) for p in real_c) < 4:
    raise UserError(f"--data: the takes are too short for {window}-frame windows")
  unseen = [y_up(m.positions) for m in scored_takes] if loss_takes == "held-out" else None
  scored = scoring.score(gen, real_c, sk, fps, train=train_c, unseen=unseen, window=window, splits=splits, seed=seed)
  return {
    "run": str(workdir),
    "checkpoint_step": run.step,
    "frames": frames,
    "num": num,
    "data": list(data),
    "sampling": {**sampling.to_dict(), "seed": seed, "seeds": seeds},
    # the first dancer, in data space: write_metrics stores it beside the JSON (compare draws its strip)
    "first_sample": Motion(decoded[0][0], fps, sk, feats.up_axis, "data", f"{Path(workdir).name} seed {seeds[0]}"),
    "loss_kind": "none" if not run.family.likelihood else "nll" if run.config.model.head == "mdn" else "mse",
    "heldout_loss": loss,
    "loss_takes": loss_takes,
    **scored,
  }


def generate_positions(run: Run, train, num: int, frames: int, seed: int, sampling: Controls) -> np.ndarray:
  """``[num, frames, J, 3]`` data-space positions; dancer k is conditioned on the k-th training take."""
  motion = run.dancer_conditions(train, num)
  return run.family.dance(run.graphdef, run.params, run.features, motion, jax.random.key(seed), frames, sampling)


def held_out(real, train_takes) -> tuple[list, str]:
  """``(the takes the loss is measured on, which they are)``: the takes of ``real`` that the run did not train
  on, ``"held-out"``; when it trained on every one of them, all of them, ``"all"`` (then the loss says how
  well the run fits its own training motion, not how it generalizes)."""
  trained = set(train_takes)
  unseen = [m for m in real if m.name not in trained]
  return (unseen, "held-out") if unseen else (list(real), "all")


def heldout_loss(run: Run, takes) -> float:
  """The model's loss on windows of ``takes`` (teacher forced; NaN if no take is long enough)."""
  enc = [(run.take_condition(m.name), np.asarray(run.features.encode(m.positions))) for m in takes]
  win = eval_windows(enc, run.config.data.seq_length, max_windows=256)
  return run.family.window_loss(run.graphdef, run.params, win) if win else float("nan")


def metrics_path(workdir) -> Path:
  """Where a run's evaluation lives by default (what `chorjax compare` and sweeps read)."""
  return Path(workdir) / "eval" / "metrics.json"


def write_metrics(result: dict, path) -> Path:
  """Writes the metrics JSON; an evaluation's first generated dancer goes to ``sample.npz`` beside it."""
  result = dict(result)
  first = result.pop("first_sample", None)
  if first is not None:
    write_motions(sample_path(path), [first], settings=result["sampling"])
  return atomic_write(path, lambda p: p.write_text(json.dumps(result, indent=2)))


def sample_path(metrics_json) -> Path:
  """The evaluation's first generated dancer, beside its metrics JSON: ``sample.npz`` beside ``metrics.json``
  (a run's ``eval/``), else ``NAME.sample.npz`` beside ``NAME.json``, so evaluations written to one folder keep
  a dancer each."""
  path = Path(metrics_json)
  return path.with_name("sample.npz" if path.name == "metrics.json" else f"{path.stem}.sample.npz")


def evaluate_to(workdir, data, output=None, *, force: bool = False, **kw) -> tuple[dict, Path]:
  """``chorjax eval``: :func:`evaluate` (``kw``: its arguments and the sampling controls), written to ``output``
  (default: the run's ``eval/metrics.json``) with its first dancer beside it; neither replaced unless
  ``force`` (checked before the draw). Returns ``(the result, the JSON written)``."""
  out = check_output(output, (".json",))[0] if output else metrics_path(workdir)
  refuse_existing([out, sample_path(out)], force)
  result = evaluate(workdir, data, **kw)
  return result, write_metrics(result, out)
