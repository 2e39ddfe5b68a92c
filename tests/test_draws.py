"""Draws do not change: tiny runs of every family, trained with fixed seeds, and the checkpoint in
tests/fixtures/legacy_run, sampled by the commands a user runs (several controls, primes, blends, BVH);
every written file's SHA-256 must equal the one recorded in tests/fixtures/draws.json.

The digests were recorded before the package was restructured, so a refactor that changes one bit of a
trained parameter or of a drawn frame fails here. CPUs differ in the last bits of the same program (XLA picks
its kernels by the instruction set), so draws.json holds one set of digests per CPU it was recorded on, and
the draws must equal one of them whole. ``CHORJAX_RECORD_DRAWS=1 python -m pytest tests/test_draws.py -n 0``
records this CPU's set (added beside the others): on a CPU not listed yet, or, with ``CHORJAX_RECORD_DRAWS=only``
(every other set dropped, since it no longer holds), after an intended change of what is drawn.
The rest of the suite compiles for speed of compiling (tests/conftest.py: QUICK_COMPILE), which changes last bits
too: the draws are made in a process of their own (``python tests/test_draws.py OUT``) without those flags, as a
user's programs compile, and with a takes cache of their own (the run's holds features the quick programs encoded).
"""

import hashlib
import json
import os
import platform
import shutil
import subprocess
import sys
from pathlib import Path

from helpers import GAN_NETWORKS, QUICKSTART_SAMPLING, tiny_config

from chorjax import cli
from chorjax.data.dataset import bundled_path
from chorjax.runtime import cpu_info
from chorjax.training import train_and_evaluate

ROOT = Path(__file__).resolve().parents[1]
DIGESTS = ROOT / "tests" / "fixtures" / "draws.json"
RECORD = os.environ.get("CHORJAX_RECORD_DRAWS", "")
TAKE = bundled_path("cmu94") / "94_10_skeleton_3d.csv"

QUIET = ["train.num_steps=3", "log.tensorboard=false", "sample.frames=16"]
FAMILIES = {
  "quickstart": [*QUICKSTART_SAMPLING, "model.mdn_basis=pca", "data.augment=['mirror']", "sample.scale_cap=0.97"],
  "mse": ["model.head=mse", "data.representation=canonical"],
  "gan": GAN_NETWORKS,
  "inbetween": [
    "model.family=inbetween",
    "model.num_layers=1",
    "inbetween.encoder_sizes=[16]",
    "inbetween.decoder_sizes=[16]",
    "inbetween.context=4",
    "inbetween.min_frames=2",
    "inbetween.max_frames=8",
  ],
}
FAMILIES["cvae"] = [
  *FAMILIES["inbetween"],
  "inbetween.system=cvae",
  "inbetween.manifold_encoder_sizes=[16]",
  "inbetween.expert_sizes=[16,16]",
  "inbetween.gate_sizes=[16]",
  "inbetween.experts=2",
  "inbetween.latent_size=4",
  "inbetween.manifold_frames=6",
  "inbetween.manifold_steps=2",
]


# name -> (run, the command's arguments after the run directory; "{out}" is the output file)
def _keys(*settings: str) -> list[str]:
  return [a for s in settings for a in ("--set", f"sample.{s}")]


SAMPLE = ["sample", "{run}", "-o", "{out}", "--frames", "24"]
BETWEEN = ["inbetween", "{run}", "--from", f"{TAKE}:100:6", "--to", f"{TAKE}:130", "--frames", "9", "-o", "{out}"]
COMMANDS = {
  "quickstart.csv": ("quickstart", [*SAMPLE, "--seed", "3"]),
  "quickstart_num2.csv": ("quickstart", [*SAMPLE, "--num", "2", "--motion", "1"]),
  "quickstart_plain.csv": (
    "quickstart",
    [*SAMPLE, *_keys("noise_smoothing=0", "persistence=0", "crossfade=0", "scale_cap=0"), "--pace", "0", "--seed", "1"],
  ),
  "quickstart_greedy.csv": ("quickstart", [*SAMPLE, "--set", "sample.greedy=true", "--no-foot-lock", "--no-ground"]),
  "quickstart_controls.csv": (
    "quickstart",
    [*SAMPLE, *_keys("pi_temperature=0.5", "noise_order=2", "clamp_steps=false"), "--sigma-temperature", "0.7"]
    + ["--pace", "1"],
  ),
  "quickstart_mix_prime.csv": ("quickstart", [*SAMPLE, "--mix", "2:0.5,3:0.5", "--prime", f"{TAKE}:10:8"]),
  "quickstart.bvh": ("quickstart", [*SAMPLE, "--seed", "2"]),
  "mse.csv": ("mse", [*SAMPLE, "--no-rigid-bones"]),
  "gan.csv": ("gan", [*SAMPLE, "--num", "2", "--seed", "4"]),
  "inbetween.csv": ("inbetween", [*BETWEEN, "--seed", "1"]),
  "cvae.csv": ("cvae", [*BETWEEN, "--num", "2"]),
  "legacy.csv": ("legacy", [*SAMPLE, "--seed", "5"]),
}


def _trained(root: Path) -> dict[str, Path]:
  """Every family's tiny run (3 steps, its end sample written) and a copy of the checkpoint written before."""
  made = {}
  for name, overrides in FAMILIES.items():
    made[name] = root / name
    train_and_evaluate(tiny_config(*QUIET, *overrides), made[name])
  made["legacy"] = shutil.copytree(ROOT / "tests" / "fixtures" / "legacy_run", root / "legacy")
  return made


def _digest(path: Path) -> str:
  return hashlib.sha256(path.read_bytes()).hexdigest()


def drawn(root: Path) -> dict[str, str]:
  """SHA-256 of every file the commands and the runs' end samples (trained under ``root``) wrote."""
  runs = _trained(root / "runs")
  found = {f"end_{name}.csv": _digest(runs[name] / "samples" / "sample.csv") for name in FAMILIES}
  for name, (run, argv) in COMMANDS.items():
    out = root / name
    args = [a.replace("{run}", str(runs[run])).replace("{out}", str(out)) for a in argv]
    assert cli.main(args) == 0, name
    found[name] = _digest(out if out.exists() else out.with_name(f"{out.stem}_0{out.suffix}"))
  return found


def this_cpu() -> str:
  """The CPU as draws.json names it: model name, family and model, and its widest vector instructions."""
  info = cpu_info()
  flags = info.get("flags", "").split()
  isa = next((f for f in ("avx512f", "avx2", "avx") if f in flags), platform.machine())
  name = info.get("model name") or platform.processor() or platform.machine()
  return f"{name} (family {info.get('cpu family', '?')}, model {info.get('model', '?')}, {isa})"


def test_draws_and_trained_parameters_are_the_recorded_ones(tmp_path):
  from conftest import QUICK_COMPILE  # here, not at the top: the child process runs this file without pytest

  flags = " ".join(f for f in os.environ.get("XLA_FLAGS", "").split() if f not in QUICK_COMPILE.split())
  made = subprocess.run(
    [sys.executable, __file__, str(tmp_path)],
    env={**os.environ, "XLA_FLAGS": flags, "CHORJAX_CACHE": str(tmp_path / "takes")},
    capture_output=True,
    text=True,
  )
  assert made.returncode == 0, made.stderr[-3000:]
  found = json.loads((tmp_path / "digests.json").read_text())
  recorded = json.loads(DIGESTS.read_text())  # CPU -> {file: SHA-256}
  if RECORD in ("1", "only"):
    recorded = {**(recorded if RECORD == "1" else {}), this_cpu(): found}
    DIGESTS.write_text(json.dumps(recorded, indent=2, sort_keys=True) + "\n")
  for cpu, digests in recorded.items():
    assert set(digests) == set(found), f"draws.json's set for {cpu} names other files"
  changed = {cpu: sorted(k for k in found if found[k] != digests[k]) for cpu, digests in recorded.items()}
  nearest = min(changed, key=lambda cpu: len(changed[cpu]))
  assert not changed[nearest], (
    f"these draws changed: {changed[nearest]} against the set recorded on {nearest}; this CPU is {this_cpu()} "
    "(see this file's docstring)"
  )


if __name__ == "__main__":  # the test above runs this in a process of its own
  (Path(sys.argv[1]) / "digests.json").write_text(json.dumps(drawn(Path(sys.argv[1]))))
