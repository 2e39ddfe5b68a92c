"""chorjax vs PyTorch on the reference model (3 x 256, batch 50, sequence 100, 48 features).

    python -m benchmarks.run            # full: every cell x head, more repetitions
    python -m benchmarks.run --quick    # < 5 minutes on 2 cores; writes benchmarks/results.json
                                        # and results_shipped.json (benchmarks.shipped), then BENCHMARKS.md's
                                        # opening table from them (benchmarks.opening)

Both frameworks run in this one process; repetitions alternate (chorjax, torch, chorjax, ...) and
medians are reported, so background load hits both sides alike. Writes ``benchmarks/results.json``
(every figure and every chorjax/PyTorch ratio, keyed by name) and prints the tables that
BENCHMARKS.md records.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks.timing import B, D, H, K, L, T, alternate, random_batch

HERE = Path(__file__).resolve().parent


def jax_train_step(cell, head):
  from chorjax.config import load_config
  from chorjax.families.recurrent.steps import create_train_state, train_step

  cfg = load_config(
    None,
    [
      f"model.cell={cell}",
      f"model.head={head}",
      f"model.num_layers={L}",
      f"model.hidden_size={H}",
      f"model.num_mixtures={K}",
      f"train.batch_size={B}",
      f"data.seq_length={T}",
    ],
  )
  state, spec = create_train_state(cfg, D, 10)
  batch = random_batch(np.random.default_rng(0), B, T, D)
  key = jax.random.key(0)
  box = {"state": state}
  t = time.perf_counter()
  step = train_step.lower(box["state"], batch, key, spec).compile()  # trace + XLA compile, timed apart from running
  compile_s = time.perf_counter() - t
  box["state"], m = step(box["state"], batch, key)
  jax.block_until_ready(m)
  first_step_s = time.perf_counter() - t

  def run():
    box["state"], m = step(box["state"], batch, key)
    return m["loss"]

  return run, compile_s, first_step_s


def torch_train_step(cell, head, variant="eager"):
  """A PyTorch train step on the reference model and the seconds its first call took (for ``compile``,
  the compile)."""
  import torch

  from benchmarks.torch_peer import Model, make_train_step

  torch.manual_seed(0)
  model = Model(cell, head, D, H, L, K, variant)
  step = make_train_step(model)
  x, y = torch.randn(B, T, D), torch.randn(B, T, D)
  t = time.perf_counter()
  step(x, y).item()
  first_s = time.perf_counter() - t
  return (lambda: step(x, y)), first_s


def train_flops(cell):
  """Matmul FLOPs of one train step (forward x 3 for forward + backward)."""
  gates = {"lstm": 4, "lnlstm": 4, "gru": 3}[cell] * H
  fwd = 0
  for l in range(L):
    d_in = D if l == 0 else H
    fwd += 2 * B * T * (d_in + H) * gates
  fwd += 2 * B * T * H * D
  return 3 * fwd


def matmul_peak():
  a = jnp.ones((2048, 2048), jnp.float32)
  f = jax.jit(lambda a: a @ a)
  f(a).block_until_ready()
  ts = []
  for _ in range(10):
    t = time.perf_counter()
    f(a).block_until_ready()
    ts.append(time.perf_counter() - t)
  return 2 * 2048**3 / float(np.median(ts))


def sampler_model():
  """``(graphdef, params)`` of the sampling rows' model: LSTM L x H with a K-component MDN over D features."""
  from flax import nnx

  from chorjax.config import load_config
  from chorjax.families.recurrent.recurrent_model import create_model

  cfg = load_config(
    None,
    ["model.cell=lstm", "model.head=mdn", f"model.num_layers={L}", f"model.hidden_size={H}", f"model.num_mixtures={K}"],
  )
  return nnx.split(create_model(cfg.model, D, 10, 0), nnx.Param)


def jax_sampler(batch):
  from chorjax.families.recurrent.generation import generate

  graphdef, params = sampler_model()
  w = jax.nn.one_hot(jnp.zeros(batch, jnp.int32), 10)
  run = lambda: generate(graphdef, params, w, jax.random.key(0), num_frames=1000)
  run().block_until_ready()
  return run


def torch_samplers(batch):
  import torch
  from torch import nn

  from benchmarks.torch_peer import sample_lstm_loop, sample_lstmcell_loop

  torch.manual_seed(0)
  cells = nn.ModuleList([nn.LSTMCell(D if l == 0 else H, H) for l in range(L)])
  lstm, out = nn.LSTM(D, H, L, batch_first=True), nn.Linear(H, K + 2 * K * D)
  return (lambda: sample_lstmcell_loop(cells, out, 1000, batch), lambda: sample_lstm_loop(lstm, out, 1000, batch))


def peak_rss_of_default_training() -> float:
  """Peak resident memory (MB) of `chorjax train configs/quickstart.toml` for 20 steps (a checkpoint,
  TensorBoard, the end sample and its player), in a child process."""
  import tempfile

  # VmHWM, not ru_maxrss: Linux carries ru_maxrss across fork+exec, so a child would report this
  # (large) benchmark process's high-water mark. VmHWM belongs to the new address space.
  code = (
    "import sys; from chorjax.cli import main; "
    "rc = main(['train', 'configs/quickstart.toml', '--workdir', sys.argv[1], 'train.num_steps=20', "
    "'log.progress=none']); "
    "print('RSS', [l.split()[1] for l in open('/proc/self/status') if l.startswith('VmHWM')][0])"
  )
  with tempfile.TemporaryDirectory() as d:
    out = subprocess.run([sys.executable, "-c", code, d], capture_output=True, text=True, cwd=HERE.parent)
  line = [l for l in out.stdout.splitlines() if l.startswith("RSS")]
  return float(line[0].split()[1]) / 1024 if line else float("nan")


def main(argv=None):
  ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
  ap.add_argument("--quick", action="store_true", help="fewer repetitions (< 5 minutes on 2 cores)")
  ap.add_argument("--out", default=str(HERE / "results.json"))
  args = ap.parse_args(argv)
  from chorjax.runtime import keep_freed_memory

  tuned = keep_freed_memory()  # as the chorjax command does; the PyTorch peer in this process gains too
  import torch

  torch.set_num_threads(os.cpu_count() or 1)
  reps = 5 if args.quick else 15
  from chorjax.compare import machine_info

  res = {
    "machine": {
      "description": machine_info(),
      "platform": platform.platform(),
      "cpus": os.cpu_count(),
      "python": platform.python_version(),
      "jax": jax.__version__,
      "torch": torch.__version__,
      "device": str(jax.devices()[0]),
      "glibc_keep_freed_memory": tuned,
    },
    "config": {"batch": B, "seq": T, "features": D, "hidden": H, "layers": L, "mixtures": K, "reps": reps},
    "train_step_s": {},
    "compile_s": {},
    "first_step_s": {},
    "torch_first_step_s": {},
    "ratio_torch_over_chorjax": {},
    "sample_1000_s": {},
  }
  peak = matmul_peak()
  kept = {}  # chorjax steps whose ratios are measured against each other, alternating in one group
  res["matmul_peak_gflops"] = peak / 1e9
  for cell in ("lstm", "lnlstm", "gru"):
    for head in ("mse", "mdn"):
      name = f"{cell}_{head}"
      jrun, compile_s, first_step_s = jax_train_step(cell, head)
      if name in ("lstm_mse", "lstm_mdn", "lnlstm_mse"):
        kept[name] = jrun
      # The LN-LSTM has no built-in PyTorch layer: its peer is measured in each form a user might write,
      # and the ratio is taken against the fastest.
      variants = ("eager", "script", "compile") if cell == "lnlstm" else ("eager",)
      peers = {}
      for v in variants:
        peers[v], res["torch_first_step_s"][f"{name}_{v}"] = torch_train_step(cell, head, v)
      sync_j, sync_t = (lambda x: jax.block_until_ready(x)), (lambda x: x.item())
      med = alternate(
        [("chorjax", jrun, sync_j), *[(f"torch_{v}", fn, sync_t) for v, fn in peers.items()]],
        reps if cell != "lnlstm" else max(3, reps // 3),
      )
      best = min(variants, key=lambda v: med[f"torch_{v}"])
      res["train_step_s"][f"chorjax_{name}"] = med["chorjax"]
      res["train_step_s"][f"torch_{name}"] = med[f"torch_{best}"]
      for v in variants:
        res["train_step_s"][f"torch_{name}_{v}"] = med[f"torch_{v}"]
        res["ratio_torch_over_chorjax"][f"train_{name}_{v}"] = med[f"torch_{v}"] / med["chorjax"]
      res["compile_s"][name] = compile_s
      res["first_step_s"][name] = first_step_s
      res["ratio_torch_over_chorjax"][f"train_{name}"] = med[f"torch_{best}"] / med["chorjax"]
      forms = "  ".join(f"torch {v} {med[f'torch_{v}'] * 1e3:7.1f} ms" for v in variants)
      print(
        f"train {name:12s} chorjax {med['chorjax'] * 1e3:7.1f} ms  {forms}  "
        f"speed-up over the fastest ({best}) {med[f'torch_{best}'] / med['chorjax']:.2f}x  "
        f"(compile {compile_s:.1f} s, first step {first_step_s:.1f} s)",
        flush=True,
      )
  ts = res["train_step_s"]
  # The LN-LSTM / LSTM and MDN / MSE ratios from one alternating group of the three chorjax steps, so
  # that the machine's drift between the groups above does not enter them.
  own = alternate([(k, v, jax.block_until_ready) for k, v in kept.items()], reps)
  res["own_group_step_s"] = own
  res["ln_over_lstm"] = own["lnlstm_mse"] / own["lstm_mse"]
  res["mdn_over_mse"] = own["lstm_mdn"] / own["lstm_mse"]
  del kept
  res["train_gflops"] = train_flops("lstm") / ts["chorjax_lstm_mse"] / 1e9
  res["train_fraction_of_peak"] = res["train_gflops"] / res["matmul_peak_gflops"]
  for batch in (1, 64):
    jrun = jax_sampler(batch)
    cell_loop, lstm_loop = torch_samplers(batch)
    med = alternate(
      [
        ("chorjax", jrun, jax.block_until_ready),
        ("lstmcell", cell_loop, lambda x: None),
        ("lstm", lstm_loop, lambda x: None),
      ],
      max(3, reps // 2),
    )
    best = min(med["lstmcell"], med["lstm"])
    for k, v in med.items():
      res["sample_1000_s"][f"{k}_b{batch}"] = v
    res["ratio_torch_over_chorjax"][f"sample_b{batch}"] = best / med["chorjax"]
    print(
      f"sample 1000 frames, batch {batch:2d}: chorjax {med['chorjax'] * 1e3:7.1f} ms  torch LSTMCell loop "
      f"{med['lstmcell'] * 1e3:7.1f} ms  nn.LSTM loop {med['lstm'] * 1e3:7.1f} ms  "
      f"speed-up {best / med['chorjax']:.2f}x",
      flush=True,
    )
  res["peak_rss_mb_default_training"] = peak_rss_of_default_training()
  print(
    f"LN-LSTM / LSTM step {res['ln_over_lstm']:.2f}x; MDN / MSE head {res['mdn_over_mse']:.2f}x; "
    f"train step {res['train_gflops']:.1f} GFLOP/s = {100 * res['train_fraction_of_peak']:.0f}% of the "
    f"{res['matmul_peak_gflops']:.0f} GFLOP/s matmul peak; default training peak RSS "
    f"{res['peak_rss_mb_default_training']:.0f} MB"
  )
  Path(args.out).write_text(json.dumps(res, indent=2))
  print(f"wrote {args.out}")
  from benchmarks import shipped  # BENCHMARKS.md's opening table: the quickstart's shape and the reference one

  shipped.OUT.write_text(json.dumps(shipped.measure(9 if args.quick else 15), indent=2))
  print(f"wrote {shipped.OUT}")
  from benchmarks import opening

  opening.write()


if __name__ == "__main__":
  main()
