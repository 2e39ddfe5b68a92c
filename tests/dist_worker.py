"""One process of the two-process data-parallel test (started by test_parallel.py).

Usage: python dist_worker.py PORT PROCESS_ID NUM_PROCESSES WORKDIR NUM_STEPS
Prints the per-step training losses of this process as one JSON line (or, stopped by a signal, where).
"""

import json
import os
import sys

os.environ["XLA_FLAGS"] = "--xla_force_host_platform_device_count=1"
os.environ["JAX_PLATFORMS"] = "cpu"
sys.path.insert(0, os.path.dirname(__file__))

from helpers import tiny_config

from chorjax.errors import Interrupted
from chorjax.training.driver import train_and_evaluate
from chorjax.training.parallel import setup_parallel

port, pid, n, workdir, steps = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], int(sys.argv[5])
cfg = tiny_config(
  f"train.num_steps={steps}",
  "train.checkpoint_every=3",
  "log.tensorboard=false",
  "parallel.distributed=true",
  f"parallel.coordinator_address='127.0.0.1:{port}'",
  f"parallel.num_processes={n}",
  f"parallel.process_id={pid}",
)
try:
  summary = train_and_evaluate(cfg, workdir, parallel=setup_parallel(cfg))
except Interrupted as e:  # a signal: every process stops after the same step (chorjax.training.loop.agreed_stop)
  print(json.dumps({"process": pid, "stopped": str(e)}), flush=True)
  sys.exit(e.code)
print(json.dumps({"process": pid, "losses": summary["train_losses"]}), flush=True)
