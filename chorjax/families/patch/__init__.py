"""The patch family (``model.family = "patch"``): no network; a dance is recombined from the training takes'
own pieces by multi-scale nearest-patch synthesis (``synthesis.py``, the method of GenMM). What a dancer with
one short take would pick: nothing to train, every frame the takes' own.

Training keeps the training takes' normalized features in the run (``patch.max_frames`` frames at most), so a
run samples, renders and evaluates as any other without its data; one step does it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import nnx

from chorjax.data.dataset import WindowSampler
from chorjax.errors import UserError
from chorjax.families.family import Family
from chorjax.families.patch.patch_config import PatchConfig
from chorjax.families.patch.synthesis import synthesize
from chorjax.registry import register


class PatchTakes(nnx.Module):
  """The takes a patch run recombines: their frames end to end ``[F, D]`` (zeros after them) and each frame's
  take ``[F]`` (-1 after them), parameters only in name (nothing trains them); and ``settings``, its
  ``[patch]`` keys (static)."""

  def __init__(self, settings: PatchConfig, dim: int, takes: Sequence[np.ndarray] = ()):
    self.settings = settings
    frames = np.zeros((settings.max_frames, dim), np.float32)
    take = np.full((settings.max_frames,), -1.0, np.float32)
    at = 0
    for i, t in enumerate(takes):
      frames[at : at + len(t)], take[at : at + len(t)] = t, i
      at += len(t)
    self.frames, self.take = nnx.Param(frames), nnx.Param(take)

  def takes(self) -> list[np.ndarray]:
    frames, take = np.asarray(self.frames[...]), np.asarray(self.take[...])
    return [frames[take == i] for i in np.unique(take[take >= 0])]


@dataclasses.dataclass(frozen=True)
class PatchSpec:
  graphdef: Any


def _keep(state, batch, key, spec):
  """The patch family's train step: nothing to learn (the step counts, so checkpoints and the end sample come)."""
  del batch, key, spec
  return {**state, "step": state["step"] + 1}, {"loss": np.float32(0.0)}


class Patch(Family):
  name = "patch"
  likelihood = False
  figures = False
  conditioned = False
  draws_frames = False  # recombined, nothing drawn frame by frame
  section = ("patch", PatchConfig)

  def refusal(self, command: str) -> str | None:
    if command == "calibrate":
      return "a patch run recombines its takes: no draw to calibrate"
    if command == "live":
      return "a patch run writes whole dances from its takes; live mode streams the rnn family"
    if command == "export":
      return "a patch run has no network to export; write its dance with chorjax sample"
    return super().refusal(command)

  def columns(self, config: dict) -> tuple[str, str]:
    return "patches", f"patch ({config['patch']['size']} frames)"

  def build_model(self, cfg, features, num_motions: int):
    return PatchTakes(cfg.patch, features.dim)

  def create_state(self, cfg, ds):
    takes = [np.asarray(x, np.float32) for _, x in ds.train]
    total, size = sum(map(len, takes)), cfg.patch.size
    if total > cfg.patch.max_frames:
      raise UserError(
        f"key 'patch.max_frames': the training takes hold {total:,} frames (augmentations included), more than "
        f"{cfg.patch.max_frames:,}; raise it or train on fewer takes"
      )
    if max(map(len, takes)) < size:
      raise UserError(f"key 'patch.size': {size} frames, longer than every training take")
    model = PatchTakes(cfg.patch, ds.features.dim, takes)
    graphdef, params = nnx.split(model, nnx.Param)
    state = {"params": nnx.to_pure_dict(params), "opt_state": (), "step": jnp.zeros((), jnp.int32)}
    return state, PatchSpec(graphdef)

  def parts(self, cfg, ds):
    return _keep, WindowSampler(ds.train, cfg.data.seq_length, 1, cfg.train.seed), {}, None

  def dance(self, graphdef, params, features, motion, key, num_frames, controls, prime=None):
    """Each dancer one recombination of the takes (``motion`` only counts them; no prime)."""
    if prime is not None:
      raise UserError("--prime: a patch run recombines its takes; it cannot continue a phrase")
    model = nnx.merge(graphdef, params)
    assert isinstance(model, PatchTakes)
    seeds = np.asarray(jax.random.randint(key, (int(np.shape(motion)[0]),), 0, 2**31 - 1))
    takes = model.takes()
    z = np.stack([synthesize(takes, num_frames, model.settings, np.random.default_rng(int(s))) for s in seeds])
    return np.asarray(features.decode(z, **controls.decoding()))


register(Patch())
