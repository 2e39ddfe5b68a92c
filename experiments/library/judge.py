"""Judges labelled-library runs per label on their held-out takes.

For every (action, style) pair of a run's held-out takes (``data.val_pattern``), the run dances
``--frames`` frames conditioned on that pair (``--motion action=A,style=S``, its own calibrated draw), and:

* a classifier fitted on the run's TRAINING takes' windows (2 s, AIST++'s kinetic and geometric features
  of ``chorjax eval``'s FIDs, logistic regression) names each 2 s window's action and style; the held-out
  takes' own windows, classified the same way, are the ceiling;
* its movement (joint travel over 0.5 s) and jitter are divided by its held-out take's, and the pooled
  samples are scored against the pooled held-out takes as ``chorjax eval`` scores a run (FID_k, FID_g).

    python experiments/library/judge.py runs/library/seed=0 runs/library/seed=1 ... -o results/judge.json

Needs scikit-learn (``pip install -e '.[experiments]'``). The JSON holds, per run, the accuracies, the
ratios to the ceiling, the confusion matrices and the per-pair measures; ``table.py`` makes the report.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import jax
import numpy as np
from sklearn.linear_model import LogisticRegression
from sklearn.metrics import confusion_matrix
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from chorjax.data import transforms
from chorjax.data.dataset import load_dataset
from chorjax.data.features import hips
from chorjax.data.transforms import to_y_up
from chorjax.evaluation import metrics, scoring
from chorjax.run import load_run

WINDOW, HOP = 60, 30  # 2 s windows at 30 fps, half overlapping
POOLED = ("movement_first", "movement_last", "jitter", "fid_k", "fid_k_real", "fid_g", "fid_g_real")


def window_features(pos_TxJx3, skeleton, size: float, fps: float) -> np.ndarray:
  """``[N, F]``: each 2 s window's kinetic and geometric features (those of FID_k and FID_g)."""
  kin = lambda w: metrics.kinetic_features(w / size, fps)
  geo = lambda w: metrics.geometric_features(w, skeleton, size).mean(0)
  rows = [np.concatenate([kin(w), geo(w)]) for w in metrics.windows(pos_TxJx3, WINDOW, HOP)]
  return np.stack(rows) if rows else np.zeros((0, 0))


def turn_rate(pos_TxJx3, skeleton, fps: float, lag_s: float = 1.0) -> float:
  """How fast the heading turns: the mean absolute change of the facing angle (from the hips) over ``lag_s``
  seconds, in degrees a second (over a second a stride's sway cancels: what is left is turning)."""
  left, right = hips(skeleton)
  angle = np.unwrap(np.asarray(transforms.heading(pos_TxJx3, left, right)))
  lag = max(round(lag_s * fps), 1)
  return float(np.degrees(np.abs(angle[lag:] - angle[:-lag]).mean()) / (lag / fps)) if len(angle) > lag else 0.0


def fit(features_by_take: dict, labels_of: dict, field: str):
  x = np.concatenate([f for f in features_by_take.values() if len(f)])
  y = np.concatenate([[labels_of[n][field]] * len(f) for n, f in features_by_take.items() if len(f)])
  return make_pipeline(StandardScaler(), LogisticRegression(max_iter=3000, C=1.0)).fit(x, y)


def _accuracy(clf, features_by_take: dict, labels_of: dict, field: str) -> float:
  hits = [(clf.predict(x) == labels_of[n][field]).mean() for n, x in features_by_take.items() if len(x)]
  return float(np.mean(hits))


def judge(workdir: Path, frames: int, seed: int, controls: dict | None = None, prime: int = 0) -> dict:
  run = load_run(workdir)
  ds = load_dataset(run.config.data)
  sk, fps, up = run.features.skeleton, run.fps, run.features.up_axis
  y_up = lambda p: np.asarray(to_y_up(p, up), np.float64)
  takes = {m.name: y_up(m.positions) for m in ds.motions}
  labels_of = {n: ds.labels.of_take(n) for n in takes}
  size = float(np.mean([metrics.body_size(takes[n], sk) for n in run.train_takes]))
  feats = {n: window_features(p, sk, size, fps) for n, p in takes.items()}
  train = {n: feats[n] for n in run.train_takes}
  # the held-out takes at least one judged window long (a run with a short data.seq_length holds out shorter ones)
  val_takes = [n for n in run.val_takes if len(feats[n])]
  held = {n: feats[n] for n in val_takes}
  fields = list(ds.labels.fields)
  classifiers = {f: fit(train, labels_of, f) for f in fields}

  pairs = [labels_of[n] for n in val_takes]
  sampling = run.sampling(**(controls or {}))
  served = run.serving("sample").ranged(sampling)
  motion = np.stack([served.motion_weights(",".join(f"{f}={p[f]}" for f in fields)) for p in pairs])
  primed = None
  if prime:  # the first frames of a training take of each pair, danced on from there
    by_name = {m.name: m for m in ds.motions}
    first = [next(n for n in run.train_takes if labels_of[n] == p and by_name[n].num_frames > prime) for p in pairs]
    primed = np.stack([np.asarray(served.features.encode(by_name[n].positions[:prime])) for n in first])
  pos = served.family.dance(
    served.graphdef, served.params, served.features, motion, jax.random.key(seed), frames, sampling, primed
  )
  samples = [y_up(p) for p in np.asarray(pos)[:, prime:]]
  sample_feats = [window_features(p, sk, size, fps) for p in samples]

  out: dict = {"run": str(workdir), "checkpoint_step": run.step, "frames": frames, "seed": seed, "prime": prime}
  out |= {"sampling": sampling.to_dict(), "fields": {}}
  for f in fields:
    clf = classifiers[f]
    truth_h = np.concatenate([[labels_of[n][f]] * len(x) for n, x in held.items()])
    pred_h = clf.predict(np.concatenate(list(held.values())))
    truth_s = np.concatenate([[p[f]] * len(x) for p, x in zip(pairs, sample_feats)])
    pred_s = clf.predict(np.concatenate(sample_feats))
    values = sorted(set(truth_h))
    ceiling, accuracy = float((pred_h == truth_h).mean()), float((pred_s == truth_s).mean())
    first = np.concatenate([clf.predict(x[:10]) == p[f] for p, x in zip(pairs, sample_feats)]).mean()
    out["fields"][f] = {
      "values": values,
      "train_accuracy": _accuracy(clf, train, labels_of, f),
      "heldout_accuracy": ceiling,
      "sample_accuracy": accuracy,
      "ratio": accuracy / ceiling,
      "sample_accuracy_first_10s": float(first),
      "confusion_heldout": confusion_matrix(truth_h, pred_h, labels=values).tolist(),
      "confusion_samples": confusion_matrix(truth_s, pred_s, labels=values).tolist(),
    }
  lag = max(round(0.5 * fps), 1)
  per_pair = []
  for p, name, s, x in zip(pairs, val_takes, samples, sample_feats):
    disp, rough = metrics.reference_rates([takes[name]], sk.root, lag)
    per_pair.append(
      {
        **p,
        "take": name,
        "movement": metrics.displacement(s, sk.root, lag) / disp,
        "jitter": metrics.roughness(s) / rough,
        "turn_rate": turn_rate(s, sk, fps),
        "take_turn_rate": turn_rate(takes[name], sk, fps),
        "sway_rate": turn_rate(s, sk, fps, 1 / fps),
        "take_sway_rate": turn_rate(takes[name], sk, fps, 1 / fps),
        **{f"{f}_accuracy": float((classifiers[f].predict(x) == p[f]).mean()) for f in fields},
      }
    )
  out["per_pair"] = per_pair
  if "action" in fields:  # the walks' turning: every walk take's, the samples' per pair above
    walks = [n for n in takes if labels_of[n]["action"] == "walk"]
    out["walk_take_turn_rates"] = [turn_rate(takes[n], sk, fps) for n in walks]
  pooled = scoring.score(samples, [takes[n] for n in val_takes], sk, fps, seed=seed)
  out["pooled"] = {k: pooled[k] for k in POOLED}
  return out


def main() -> None:
  ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  ap.add_argument("runs", nargs="+", type=Path)
  ap.add_argument("--frames", type=int, default=2000)
  ap.add_argument("--seed", type=int, default=0)
  ap.add_argument("-o", "--output", type=Path, required=True)
  ap.add_argument("--prime", type=int, default=0, help="prime each pair with this many frames of a training take")
  ap.add_argument("--control", action="append", default=[], help="a sampling control, KEY=VALUE (e.g. pace=0)")
  args = ap.parse_args()
  results = []
  for w in args.runs:
    controls = {k: json.loads(v) for k, v in (c.split("=", 1) for c in args.control)}
    r = judge(w, args.frames, args.seed, controls, args.prime)
    results.append(r)
    for f, v in r["fields"].items():
      print(
        f"{w} {f}: held-out {v['heldout_accuracy']:.3f} samples {v['sample_accuracy']:.3f} ratio {v['ratio']:.2f}"
        f" (first 10 s: {v['sample_accuracy_first_10s']:.3f})"
      )
    for key in ("movement", "jitter"):
      v = np.array([p[key] for p in r["per_pair"]])
      print(f"{w} {key}: median {np.median(v):.2f}, {np.mean((v >= 0.7) & (v <= 1.3)):.0%} of pairs in 0.7-1.3")
  args.output.parent.mkdir(parents=True, exist_ok=True)
  args.output.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
  main()
