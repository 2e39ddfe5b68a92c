"""Data parallelism: 4 forced host devices and 2 processes (jax.distributed, gloo) match one device."""

import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest
from helpers import tiny_config

from chorjax import cli
from chorjax.training.driver import train_and_evaluate
from chorjax.training.parallel import setup_parallel

HERE = Path(__file__).resolve().parent


def losses(summary):
  return np.array([summary["train_losses"][s] for s in sorted(summary["train_losses"])])


def test_four_devices_match_one_device(tmp_path):
  assert jax.device_count() == 4  # conftest forces 4 host devices before jax starts
  base = ["train.num_steps=5", "train.batch_size=8", "log.tensorboard=false", "sample.frames=1"]
  single = train_and_evaluate(tiny_config(*base), tmp_path / "single")
  cfg = tiny_config(*base, "parallel.data_parallel=true")
  par = setup_parallel(cfg)
  assert par.mesh.shape == {"data": 4}
  multi = train_and_evaluate(cfg, tmp_path / "multi", parallel=par)
  assert len(losses(single)) == 5
  np.testing.assert_allclose(losses(multi), losses(single), rtol=1e-5, atol=1e-5)
  # the batch really was sharded: each device holds 2 of the 8 rows
  from chorjax.data.dataset import WindowSampler, load_dataset

  ds = load_dataset(cfg.data)
  b = par.global_batch(WindowSampler(ds.train, cfg.data.seq_length, 8, 0), 0)
  assert {s.data.shape[0] for s in b["inputs"].addressable_shards} == {2}


def test_batch_must_divide_over_devices(capsys):
  assert cli.main(["config", "show", "parallel.data_parallel=true"]) == 0
  from chorjax.errors import UserError

  with pytest.raises(UserError, match="divisible by the 4 devices"):
    setup_parallel(tiny_config("parallel.data_parallel=true", "train.batch_size=6"))


def free_port() -> int:
  with socket.socket() as s:
    s.bind(("127.0.0.1", 0))
    return s.getsockname()[1]


@pytest.mark.slow
def test_two_processes_match_a_single_process_and_resume_on_one(tmp_path):
  port, steps = free_port(), 3
  env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
  procs = [
    subprocess.Popen(
      [sys.executable, str(HERE / "dist_worker.py"), str(port), str(i), "2", str(tmp_path / "dist"), str(steps)],
      stdout=subprocess.PIPE,
      stderr=subprocess.PIPE,
      text=True,
      env=env,
    )
    for i in range(2)
  ]
  outs = [p.communicate(timeout=300) for p in procs]
  for p, (_, err) in zip(procs, outs):
    assert p.returncode == 0, err[-2000:]
  reports = [json.loads(out.strip().splitlines()[-1]) for out, _ in outs]
  # the single-process reference with the same global batch (4 windows)
  single = train_and_evaluate(
    tiny_config(f"train.num_steps={steps}", "train.checkpoint_every=3", "log.tensorboard=false"), tmp_path / "single"
  )
  for r in reports:
    got = np.array([r["losses"][str(s)] for s in sorted(map(int, r["losses"]))])
    np.testing.assert_allclose(got, losses(single), rtol=1e-5, atol=1e-5)
  # only process 0 wrote logs; the collective checkpoint resumes in one process
  assert (tmp_path / "dist" / "metrics.jsonl").exists()
  assert (tmp_path / "dist" / "checkpoints" / "3").is_dir()
  more = train_and_evaluate(
    tiny_config("train.num_steps=5", "train.checkpoint_every=3", "log.tensorboard=false"), tmp_path / "dist"
  )  # another process count: no --force needed
  ref = train_and_evaluate(
    tiny_config("train.num_steps=5", "train.checkpoint_every=3", "log.tensorboard=false"), tmp_path / "single"
  )
  assert more["start_step"] == 3 and ref["start_step"] == 3
  np.testing.assert_allclose(losses(more), losses(ref), rtol=1e-5, atol=1e-5)


def test_a_signal_to_one_process_stops_both_after_the_same_step_with_a_checkpoint(tmp_path):
  import signal
  import time

  port, work = free_port(), tmp_path / "dist"
  env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
  procs = [
    subprocess.Popen(
      [sys.executable, str(HERE / "dist_worker.py"), str(port), str(i), "2", str(work), "100000"],
      stdout=subprocess.PIPE,
      stderr=subprocess.PIPE,
      text=True,
      env=env,
    )
    for i in range(2)
  ]
  log, deadline = work / "metrics.jsonl", time.time() + 240
  while not (log.exists() and len(log.read_text().splitlines()) >= 3):  # both are training
    assert all(p.poll() is None for p in procs) and time.time() < deadline, procs[0].stderr.read()[-2000:]
    time.sleep(0.2)
  procs[1].send_signal(signal.SIGTERM)  # a preempted host: the other one is not told by anyone else
  outs = [p.communicate(timeout=120) for p in procs]
  assert [p.returncode for p in procs] == [143, 143], [err[-1500:] for _, err in outs]
  stopped = [json.loads(out.strip().splitlines()[-1])["stopped"] for out, _ in outs]
  assert stopped[0] == stopped[1] and stopped[0].startswith("SIGTERM at step ")
  step = int(stopped[0].split()[3].split("/")[0])
  assert (work / "checkpoints" / str(step)).is_dir()  # written by both, together
  more = train_and_evaluate(
    tiny_config(f"train.num_steps={step + 2}", "train.checkpoint_every=3", "log.tensorboard=false"), work
  )
  assert more["start_step"] == step and more["final_step"] == step + 2


@pytest.mark.slow
def test_cli_distributed_flags_launch_two_processes(tmp_path):
  from chorjax.config import to_toml

  cfg = tmp_path / "c.toml"
  cfg.write_text(to_toml(tiny_config("train.num_steps=2", "log.tensorboard=false", "sample.frames=1")))
  port = free_port()
  env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
  procs = [
    subprocess.Popen(
      [
        sys.executable,
        "-m",
        "chorjax.cli",
        "train",
        str(cfg),
        "--workdir",
        str(tmp_path / "w"),
        "--distributed",
        "--coordinator",
        f"127.0.0.1:{port}",
        "--num-processes",
        "2",
        "--process-id",
        str(i),
      ],
      stdout=subprocess.PIPE,
      stderr=subprocess.PIPE,
      text=True,
      env=env,
    )
    for i in range(2)
  ]
  outs = [p.communicate(timeout=300) for p in procs]
  assert [p.returncode for p in procs] == [0, 0], outs[0][1][-1500:] + outs[1][1][-1500:]
  assert "trained w: steps 0->2" in outs[0][0] and "process 1/2: steps 0->2" in outs[1][0]  # named by its folder
  rows = [json.loads(l) for l in (tmp_path / "w" / "metrics.jsonl").read_text().splitlines()]
  final = float(outs[1][0].split("final train loss ")[1])
  assert final == pytest.approx(rows[-1]["train_loss"], rel=1e-5)
  assert not list((tmp_path / "w").glob("events.*")) and (tmp_path / "w" / "samples" / "sample.csv").exists()
