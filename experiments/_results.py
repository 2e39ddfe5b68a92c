"""What the experiments' table scripts share: the small files of a run kept in the repository (runs/ is not),
and the filmstrip pair every table ends with (the end of a generated dance beside a held-out take).

A script in experiments/NAME/ imports it with ``sys.path.insert(0, str(Path(__file__).parent.parent))``.
"""

import json
import shutil
from pathlib import Path

# A run's small files: enough for every table to be rebuilt on a machine without the runs.
KEPT = ("config.json", "calibration.json", "metrics.jsonl", "eval/metrics.json")


def keep_small_files(run: Path, dest: Path) -> None:
  """Copies the ``KEPT`` files of an evaluated run to ``dest/<run name>/``."""
  for name in KEPT:
    if (run / name).exists():
      (dest / run.name / name).parent.mkdir(parents=True, exist_ok=True)
      shutil.copyfile(run / name, dest / run.name / name)


def takes_as_trained(run: Path):
  """``(the run's dataset as training loaded it, every take of it by name, conformed as training read them)``,
  from its config.json alone (no checkpoint needed: runs trained elsewhere keep only their small files)."""
  from chorjax.config import config_from_dict
  from chorjax.data.dataset import conform, load_dataset, read_takes

  cfg = config_from_dict(json.loads((run / "config.json").read_text())).data
  return load_dataset(cfg), {m.name: m for m in conform(read_takes([cfg.dataset], cfg), cfg)}


def held_out_take(run: Path):
  """The first take of the run's dataset that it did not train on, read as its training read it."""
  ds, every = takes_as_trained(run)
  trained = set(ds.train_names)
  return next(m for name, m in every.items() if name not in trained)


def end_strip(sample: Path, png: Path, title: str, frames: int = 900) -> None:
  """The last ``frames`` frames of the first dancer in an eval's sample.npz as a filmstrip."""
  from chorjax.data.npz import read_npz
  from chorjax.render.plot import plot_strip

  dance = read_npz(sample)[0]
  n = len(dance.positions)
  name = f"{title}: frames {n - frames + 1:,}-{n:,}"
  plot_strip(dance.replace(positions=dance.positions[-frames:], name=name), png, every=10, poses=12)


def real_strip(run: Path, png: Path, dataset: str) -> None:
  """A held-out take of the run's dataset as a filmstrip, drawn as the generated ones are."""
  from chorjax.render.plot import plot_strip

  real = held_out_take(run)
  plot_strip(real.replace(name=f"{dataset} held-out take {real.name}"), png, every=10, poses=12)
