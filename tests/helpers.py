"""Small shared helpers for tests: tiny configs that keep the suite fast on 2 CPU cores."""

import struct
from pathlib import Path

from chorjax.config import load_config

ROOT = Path(__file__).resolve().parents[1]
BLENDER_PYTHON = ROOT / ".venv" / "blender" / "bin" / "python"  # .ci/run: a venv with the bpy package

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


# a tiny LSTM-GAN (model.family = "gan")
GAN_NETWORKS = [
  "model.family=gan",
  "data.representation=directions",
  "gan.latent_size=8",
  "gan.generator_dense=[16]",
  "gan.generator_size=16",
  "gan.critic_size=16",
  "gan.critic_dense=[16]",
  "gan.generator_layers=1",
  "gan.critic_layers=1",
]


# the quickstart's way of drawing: smoothed noise, persistence, crossfade, clamp, pace, rigid bones, foot lock
QUICKSTART_SAMPLING = [
  "data.representation=canonical",
  "sample.noise_smoothing=0.9",
  "sample.persistence=6.0",
  "sample.crossfade=0.8",
  "sample.clamp=true",
  "sample.pace=0.5",
  "sample.rigid_bones=true",
  "sample.foot_lock=true",
]


def headless(profile, page: str, *flags: str, timeout: int = 120, **kw):
  """Runs headless Chromium on ``page`` (a URL) with ``flags`` (``--dump-dom``, ``--screenshot=...``) and a
  fresh profile; the completed process (``stdout`` holds a dumped DOM)."""
  import subprocess

  from test_sample_render import chromium

  base = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--no-first-run"]
  cmd = [chromium(), *base, f"--user-data-dir={profile}", *flags, page]
  return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, **kw)


def tiny_config(*overrides, path=None):
  """The defaults shrunk to toy sizes (hidden 16, 2 layers, T 12, batch 4, 2 steps)."""
  return load_config(path, [*TINY, *overrides])


def read_events(event_file: Path) -> tuple[dict, dict]:
  """Reads a TensorBoard event file with tensorboardX's bundled protobufs: (scalars, images) by tag."""
  from tensorboardX.proto import event_pb2

  data, scalars, images, i = event_file.read_bytes(), {}, {}, 0
  while i < len(data):
    (n,) = struct.unpack("<Q", data[i : i + 8])
    ev = event_pb2.Event.FromString(data[i + 12 : i + 12 + n])
    i += 12 + n + 4
    for v in ev.summary.value:
      if v.HasField("image"):
        images.setdefault(v.tag, []).append((ev.step, v.image.encoded_image_string))
      else:
        scalars.setdefault(v.tag, []).append((ev.step, v.simple_value))
  return scalars, images


def read_or_refused(path: Path, **kw):
  """The motions read from ``path``, or None after a one-line ``UserError`` that names the file; whatever is
  accepted must be finite and hold frames (the property every reader test asserts)."""
  import numpy as np

  from chorjax.data.dataset import read_motions
  from chorjax.errors import UserError

  try:
    motions = read_motions(path, **kw)
  except UserError as e:
    assert "\n" not in str(e) and (path.name in str(e) or str(path.parent) in str(e)), str(e)
    return None
  for m in motions:
    assert m.num_frames > 0 and np.isfinite(m.positions).all()
  return motions
