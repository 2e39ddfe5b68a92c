"""``chorjax eval``: held-out likelihood plus the generation metrics of ``chorjax.metrics`` for a run."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import jax
import numpy as np

from chorjax import metrics
from chorjax.data.dataset import conform, eval_windows, read_takes
from chorjax.data.transforms import to_y_up
from chorjax.errors import UserError, atomic_write
from chorjax.run import Run, load_run
from chorjax.sample import generate
from chorjax.train import eval_step


def evaluate(
  workdir,
  data: Sequence[str],
  *,
  frames: int = 10_000,
  num: int = 4,
  checkpoint="latest",
  seed: int = 0,
  pi_temperature=None,
  sigma_temperature=None,
  greedy=None,
  window: int = 60,
) -> dict:
  """Samples ``num`` dancers of ``frames`` frames and measures them against the takes in ``data``.

  Args:
    workdir: a run directory.
    data: bundled names, folders or files: the real motion to compare with (e.g. the held-out take).
    frames, num: length and count of generated sequences (dancer k is conditioned on the k-th
      training take, round robin).
    window: frames per window for FID_k, Div_k and novelty (60 = 2 s at 30 fps).
    pi_temperature, sigma_temperature, greedy: sampling controls; default: the run's ``[sample]``.

  Returns:
    A flat dict of metrics (JSON-ready); see the README for each entry.
  """
  run = load_run(workdir, checkpoint)
  feats = run.features
  sk, fps = feats.skeleton, run.fps
  sampling = run.sampling(pi_temperature, sigma_temperature, greedy)
  real, train = read_reference(run, data)
  if frames < 2 * window:
    raise UserError(f"--frames {frames}: need at least {2 * window} frames")

  loss = heldout_loss(run, real)
  ids = [run.id_map[m.name] for m in train] or [0]
  motion = np.array([ids[k % len(ids)] for k in range(num)])
  z = generate(run.graphdef, run.params, motion, jax.random.key(seed), num_frames=frames, **sampling)
  y_up = lambda pos: np.asarray(to_y_up(pos, feats.up_axis))  # data space -> y-up: what the metrics measure
  gen = [y_up(p) for p in np.asarray(feats.decode(z))]
  real_c = [y_up(m.positions) for m in real]
  train_c = [y_up(m.positions) for m in train]

  size = float(np.mean([metrics.body_size(p, sk) for p in train_c]))
  data_speed = float(np.mean(np.concatenate([metrics.joint_speed(p) for p in train_c])))
  curves = np.stack([metrics.freeze_curve(g, data_speed, 100) for g in gen])
  last = min(1000, frames // 2)
  cv_gen = [metrics.bone_cv(g, sk) for g in gen]
  cv_real = [metrics.bone_cv(p, sk) for p in real_c]

  def kin(wins):
    return np.stack([metrics.kinetic_features(x / size, fps) for x in wins])

  gen_w = np.concatenate([metrics.windows(g, window, window) for g in gen])
  real_w = np.concatenate([metrics.windows(p, window, window // 4) for p in real_c])
  train_w = np.concatenate([metrics.windows(p, window, window // 4) for p in train_c])
  if len(real_w) < 2:
    raise UserError(f"--data: the takes give {len(real_w)} windows of {window} frames; need at least 2")
  fid = metrics.fid_k(kin(real_w), kin(gen_w))
  ref = metrics.fid_k(kin(real_w), kin(train_w))
  return {
    "run": str(workdir),
    "checkpoint_step": run.step,
    "frames": frames,
    "num": num,
    "data": list(data),
    "sampling": {**sampling, "seed": seed},
    "loss_kind": "nll" if run.config.model.head == "mdn" else "mse",
    "heldout_loss": loss,
    "freeze_ratio_first_1000": float(np.mean([metrics.freeze_ratio(g[: last + 1], data_speed) for g in gen])),
    "freeze_ratio_last_1000": float(np.mean([metrics.freeze_ratio(g[-last - 1 :], data_speed) for g in gen])),
    "freeze_curve": curves.mean(0).tolist(),
    "bone_cv_median": float(np.mean([c["median"] for c in cv_gen])),
    "bone_cv_max": float(np.mean([c["max"] for c in cv_gen])),
    "data_bone_cv_median": float(np.mean([c["median"] for c in cv_real])),
    "foot_sliding": float(np.mean([metrics.foot_sliding(g, sk, fps, size) for g in gen])),
    "data_foot_sliding": float(np.mean([metrics.foot_sliding(p, sk, fps, size) for p in real_c])),
    "fid_k": fid["fid_k"],
    "div_k": fid["div_k"],
    "data_div_k": fid["real_div_k"],
    "real_fid_k": ref["fid_k"],
    "real_train_div_k": ref["div_k"],
    "novelty": metrics.novelty(gen_w / size, train_w / size, sk.root),
    "real_novelty": metrics.novelty(real_w / size, train_w / size, sk.root),
    "body_size": float(size),
    "window": window,
  }


def read_reference(run: Run, data: Sequence[str]) -> tuple[list, list]:
  """``(the takes in data, the run's training takes)``, read exactly as training read its takes."""
  data_cfg = run.config.data
  real = conform(read_takes(list(data), data_cfg), data_cfg)
  if not real:
    raise UserError(f"--data {' '.join(data)}: no takes")
  train = conform(read_takes([data_cfg.dataset], data_cfg), data_cfg)
  return real, [m for m in train if m.name in set(run.train_takes)] or train


def heldout_loss(run: Run, takes) -> float:
  """The model's loss on windows of ``takes`` (teacher forced; NaN if no take is long enough)."""
  enc = [(run.id_map.get(m.name, 0), np.asarray(run.features.encode(m.positions))) for m in takes]
  win = eval_windows(enc, run.config.data.seq_length, max_windows=256)
  return float(eval_step(run.params, win, run.graphdef)) if win else float("nan")


def metrics_path(workdir) -> Path:
  """Where a run's evaluation lives by default (what `chorjax compare` and sweeps read)."""
  return Path(workdir) / "eval" / "metrics.json"


def write_metrics(result: dict, path) -> Path:
  return atomic_write(path, lambda p: p.write_text(json.dumps(result, indent=2)))
