"""The exported dancer's speed: frames per second of the ONNX step in onnxruntime (batch 1, one call a frame,
as a game engine or a web page calls it) beside chorjax's own streams of the same run: live mode's chunks
(fps / 8 frames a call) and one long ``chorjax sample`` draw.

    python -m benchmarks.onnx_step RUN [--frames 2000] [--out benchmarks/results_onnx.json]

RUN is a trained run (its shape is what is timed; e.g. the quick start's runs/quickstart). Each figure is the
median of 5 timed repetitions after one untimed one, on this machine's CPU.
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def median_rate(frames: int, once, reps: int = 5) -> float:
  """Frames per second of ``once()`` (which makes ``frames`` frames): the median over ``reps`` timed calls."""
  once()
  times = []
  for _ in range(reps):
    t = time.perf_counter()
    once()
    times.append(time.perf_counter() - t)
  return frames / float(np.median(times))


def main(argv=None) -> dict:
  parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
  parser.add_argument("run", help="a trained run directory")
  parser.add_argument("--frames", type=int, default=2000)
  parser.add_argument("--out", default=str(HERE / "results_onnx.json"))
  args = parser.parse_args(argv)

  import jax

  from chorjax.api import load_run
  from chorjax.export.dancer import OnnxDancer, sample_numbers
  from chorjax.models import motion_weight_vector

  run = load_run(args.run)
  n = args.frames
  with tempfile.TemporaryDirectory() as where:
    path = Path(where) / "dancer.onnx"
    run.export(path)
    dancer = OnnxDancer(path)
    k, d = dancer.meta["num_mixtures"], dancer.meta["dim"]
    gumbel, normal = sample_numbers(run, 0, n)
    weights = motion_weight_vector(run.num_motions)[None]
    onnx_fps = median_rate(n, lambda: dancer.dance(weights, gumbel, normal))

  sampling = run.sampling()
  ranged = run.ranged(sampling)
  draw = sampling.draw(ranged.features)
  start, step = ranged.family.stream()
  chunk = max(round(ranged.fps / 8), 1)

  def live():
    state = start(ranged.graphdef, ranged.params, weights, draw)
    for i in range(n // chunk):
      state, z = step(ranged.graphdef, ranged.params, state, jax.random.key(i), draw, num_frames=chunk)
    jax.block_until_ready(z)

  live_fps = median_rate(n // chunk * chunk, live)
  key = jax.random.key(0)
  generate = lambda: ranged.family.dance(ranged.graphdef, ranged.params, ranged.features, weights, key, n, sampling)
  sample_fps = median_rate(n, generate)
  import onnxruntime

  result = {
    "run": str(args.run),
    "shape": f"{run.config.model.num_layers} x {run.config.model.hidden_size} {run.config.model.cell}, "
    f"{run.config.model.head} ({k} components), {d} features",
    "frames": n,
    "onnx_fps_batch1": round(onnx_fps),
    "live_fps_chunks": round(live_fps),
    "live_chunk": chunk,
    "sample_fps_with_decode": round(sample_fps),
    "versions": {"jax": jax.__version__, "onnxruntime": onnxruntime.__version__},
    "machine": f"{platform.processor() or platform.machine()}, {__import__('os').cpu_count()} cores",
    "date": time.strftime("%Y-%m-%d"),
  }
  Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
  print(json.dumps(result, indent=1))
  return result


if __name__ == "__main__":
  main()
