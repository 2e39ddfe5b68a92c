"""Small shared helpers for tests: tiny configs that keep the suite fast on 2 CPU cores."""

from chorjax.config import load_config

TINY = [
  "model.hidden_size=16",
  "model.num_layers=2",
  "model.num_mixtures=3",
  "data.seq_length=12",
  "train.batch_size=4",
  "train.num_steps=2",
  "train.log_every=1",
  "train.eval_every=0",
  "train.val_windows=4",
  "sample.frames=20",
  "log.progress=none",
]


def tiny_config(*overrides, path=None):
  """The defaults shrunk to toy sizes (hidden 16, 2 layers, T 12, batch 4, 2 steps)."""
  return load_config(path, [*TINY, *overrides])
