"""In-betweening (``model.family = "inbetween"``): the frames between a context phrase and a target pose.

Space. A transition is modelled in its window's own local frame: y-up positions (``Features.canonical``)
in units of the training takes' leg length, the origin under the root at the last context frame and that
frame facing +z (``Space``). Poses are flat ``[K = 3J]`` vectors. A transition of ``n`` frames is the
``n`` frames between the last context frame and the target (which stands ``n + 1`` frames after it).

Training (:func:`inbetween_train_step`, run by ``chorjax.training.driver``'s loop with its checkpoints, metrics and
resume): batches of windows of ``context + max_frames + 1`` frames from the training takes (mirrored
copies with ``data.augment = ["mirror"]``), each row its own transition length drawn from
``min_frames..max_frames`` and its target the frame that length after the context; the model writes the
whole transition feeding itself its own frames (``models.inbetween.rollout``) and the loss is the L1
distance to the real frames plus ``velocity_weight`` x the L1 distance of their frame-to-frame steps (the
step into the target included). The validation loss: the pose L1 on fixed windows of the held-out takes,
without noise.

Writing (:func:`write_transitions`): context and target go in as data-space positions and come out
unchanged, the generated frames between them. The evaluation (LaFAN1's protocol, its baselines) is
``benchmarks/lafan1.py``.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import nnx

from chorjax.config import Config
from chorjax.data import transforms
from chorjax.data.features import Features, hips
from chorjax.data.motion import chain_length
from chorjax.errors import UserError
from chorjax.families.inbetween import cvae_training as cvae
from chorjax.families.inbetween.cvae_model import transition_model
from chorjax.families.inbetween.lstm_model import balanced, rollout, transition_l1, up_to_target, window_target
from chorjax.optimizer import create_optimizer, step_key

VAL_LENGTHS = (5, 15, 30)  # transition lengths of the validation windows (cycled; at most max_frames)


# ---------------------------------------------------------------- the local space


@dataclasses.dataclass(frozen=True)
class Space:
  """A window's local frame: y-up canonical positions -> flat poses in leg lengths about an anchor frame."""

  root: int
  left: int
  right: int
  size: float

  @classmethod
  def of(cls, features: Features) -> Space:
    sk = features.skeleton
    if features.lengths is None:
      raise UserError("in-betweening needs the run's bone lengths (a run trained before they were recorded)")
    lengths = {j: float(features.lengths[j]) for j in range(sk.num_joints)}
    left, right = hips(sk)
    return cls(sk.root, left, right, float(chain_length(lengths, sk, sk.feet[0])))

  def anchor(self, canon_xJx3) -> tuple[np.ndarray, np.ndarray]:
    """``(heading [...], floor point [..., 3])`` of frames ``[..., J, 3]``."""
    across = canon_xJx3[..., self.left, :] - canon_xJx3[..., self.right, :]
    theta = np.arctan2(-across[..., 2], across[..., 0])
    return theta, canon_xJx3[..., self.root, :] * np.array([1.0, 0.0, 1.0], np.float32)

  def to_local(self, canon_xTxJx3, anchor) -> np.ndarray:
    """Canonical frames ``[..., T, J, 3]`` -> flat local poses ``[..., T, 3J]`` about ``anchor``."""
    theta, floor = anchor
    moved = canon_xTxJx3 - np.asarray(floor)[..., None, None, :]
    out = _rotate_y(moved, -np.asarray(theta)[..., None, None]) / self.size
    return out.reshape(*out.shape[:-2], -1).astype(np.float32)

  def from_local(self, flat_xTxK, anchor) -> np.ndarray:
    theta, floor = anchor
    pos = np.asarray(flat_xTxK).reshape(*np.shape(flat_xTxK)[:-1], -1, 3) * self.size
    return (_rotate_y(pos, np.asarray(theta)[..., None, None]) + np.asarray(floor)[..., None, None, :]).astype(
      np.float32
    )


def _rotate_y(v, angle):
  c, s = np.cos(angle), np.sin(angle)
  x, y, z = v[..., 0], v[..., 1], v[..., 2]
  return np.stack([c * x + s * z, y, -s * x + c * z], -1)


def training_takes(ds, augment) -> list[np.ndarray]:
  """The training takes as canonical positions ``[T, J, 3]``, with their mirror images and/or the takes
  played backwards as ``augment`` (``data.augment``) asks."""
  f = ds.features
  by_name = {m.name: m for m in ds.motions}
  out = []
  for name in ds.train_names:
    canon = np.asarray(f.canonical(by_name[name].positions), np.float32)
    versions = [canon]
    if "mirror" in augment:
      versions.append(np.asarray(transforms.mirror(canon, f.skeleton.twins, lateral_axis=0), np.float32))
    if "reverse" in augment:
      versions += [v[::-1].copy() for v in versions]
    out += versions
  return out


def held_out_takes(ds) -> list[np.ndarray]:
  by_name = {m.name: m for m in ds.motions}
  return [np.asarray(ds.features.canonical(by_name[n].positions), np.float32) for n in ds.val_names]


def local_windows(space: Space, windows_NxWxJx3, context: int) -> np.ndarray:
  """Windows of canonical frames -> flat local poses, each about its own last context frame."""
  return space.to_local(windows_NxWxJx3, space.anchor(windows_NxWxJx3[:, context - 1]))


class TransitionSampler:
  """Deterministic training batches: batch ``step`` depends only on (seed, step), like ``WindowSampler``.

  ``batch(step)``: ``{"window": [B, C + N + 1, K], "length": [B]}``, each row a random window of a
  training take (chosen by length) and a transition length from ``min_frames..max_frames``."""

  def __init__(self, takes, space: Space, ib, batch_size: int, seed: int):
    self.span = ib.context + ib.max_frames + 1
    self.takes = [t for t in takes if len(t) >= self.span]
    if not self.takes:
      raise UserError(f"no training take holds a window of {self.span} frames (inbetween.context + max_frames + 1)")
    self.space, self.ib, self.batch_size, self.seed = space, ib, batch_size, seed
    lengths = np.array([len(t) for t in self.takes], np.float64)
    self.probs = lengths / lengths.sum()

  def batch(self, step: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng((self.seed, step))
    which = rng.choice(len(self.takes), size=self.batch_size, p=self.probs)
    starts = [int(rng.integers(0, len(self.takes[i]) - self.span + 1)) for i in which]
    lengths = rng.integers(self.ib.min_frames, self.ib.max_frames + 1, size=self.batch_size)
    wins = np.stack([self.takes[i][s : s + self.span] for i, s in zip(which, starts)])
    return {"window": local_windows(self.space, wins, self.ib.context), "length": lengths.astype(np.int32)}


def spans(takes, span: int, hop: int) -> list[tuple[int, np.ndarray]]:
  """``(take index, frames)`` of every window of ``span`` frames, every ``hop`` frames of each take."""
  return [(i, t[s : s + span]) for i, t in enumerate(takes) for s in range(0, len(t) - span + 1, hop)]


def validation_batch(takes, space: Space, ib, max_windows: int, hop: int = 40) -> dict:
  """Fixed held-out windows (every ``hop`` frames, at most ``max_windows``), lengths cycling ``VAL_LENGTHS``."""
  wins = [w for _, w in spans(takes, ib.context + ib.max_frames + 1, hop)]
  if not wins:
    return {}
  keep = np.unique(np.linspace(0, len(wins) - 1, min(max_windows, len(wins))).astype(int))
  lengths = [min(VAL_LENGTHS[i % len(VAL_LENGTHS)], ib.max_frames) for i in range(len(keep))]
  window = local_windows(space, np.stack([wins[k] for k in keep]), ib.context)
  return {"window": window, "length": np.array(lengths, np.int32)}


# ---------------------------------------------------------------- training


@dataclasses.dataclass(frozen=True)
class InbetweenSpec:
  """What the in-betweening train step needs besides its arrays (hashable: a static jit argument)."""

  graphdef: Any
  tx: optax.GradientTransformation
  schedule: optax.Schedule
  context: int
  max_frames: int
  target_noise: float
  velocity_weight: float
  width: int  # the encoders' output size (the z_target noise's)


def check_inbetween(cfg: Config) -> None:
  """Raises UserError, naming the key, for an in-betweening config that cannot train."""
  ib = cfg.inbetween
  if ib.min_frames > ib.max_frames:
    raise UserError(f"inbetween.min_frames ({ib.min_frames}) is above inbetween.max_frames ({ib.max_frames})")
  for key in ("encoder_sizes", "decoder_sizes"):
    sizes = getattr(ib, key)
    if not all(isinstance(v, int) and v > 0 for v in sizes) or (key == "encoder_sizes" and not sizes):
      raise UserError(f"inbetween.{key}: expected a list of positive layer sizes, got {list(sizes)}")
  if cfg.train.feedback != "none":
    raise UserError("train.feedback: the in-betweening family always feeds itself; set train.feedback = 'none'")
  if cfg.model.dropout > 0:
    raise UserError("model.dropout: the in-betweening family runs its core frame by frame, without dropout; set 0")
  if ib.system == "cvae":
    for key in ("manifold_encoder_sizes", "expert_sizes", "gate_sizes"):
      sizes = getattr(ib, key)
      if not sizes or not all(isinstance(v, int) and v > 0 for v in sizes):
        raise UserError(f"inbetween.{key}: expected a list of positive layer sizes, got {list(sizes)}")
    if cfg.train.num_steps <= ib.manifold_steps:
      raise UserError(
        f"train.num_steps ({cfg.train.num_steps}) must be above inbetween.manifold_steps ({ib.manifold_steps}): "
        "the transition sampler trains in the steps after the manifold"
      )
    if ib.manifold_frames > ib.max_frames + 1:
      raise UserError(f"inbetween.manifold_frames ({ib.manifold_frames}) must be at most max_frames + 1")


def create_inbetween_state(cfg: Config, features: Features) -> tuple[dict, InbetweenSpec | cvae.CvaeSpec]:
  """``({params, opt_state, step}, spec)`` for a fresh in-betweening run (either system)."""
  check_inbetween(cfg)
  if cfg.inbetween.system == "cvae":
    return cvae.create_cvae_state(cfg, features, Space.of(features))
  graphdef, params = nnx.split(transition_model(cfg, features), nnx.Param)
  params = nnx.to_pure_dict(params)
  tx, schedule = create_optimizer(cfg)
  ib = cfg.inbetween
  spec = InbetweenSpec(
    graphdef, tx, schedule, ib.context, ib.max_frames, ib.target_noise, ib.velocity_weight, ib.encoder_sizes[-1]
  )
  return {"params": params, "opt_state": tx.init(params), "step": jnp.zeros((), jnp.int32)}, spec


def _predict(params, batch, z_BxE, spec: InbetweenSpec):
  """The model's transitions of ``batch``: ``(written frames [B, N, K], real ones [B, N + 1, K] with the
  target)``."""
  model = nnx.merge(spec.graphdef, params)
  c, n = spec.context, spec.max_frames
  window, length = batch["window"], batch["length"]
  written = rollout(model, window[:, :c], window_target(window, c, length), length, n, z_BxE)
  return written, window[:, c : c + n + 1]


def transition_loss(params, batch, key, spec: InbetweenSpec):
  """``(loss, {pose_l1, step_l1})``: the L1 distances of the written frames and of their frame-to-frame
  steps (the step into the target included) to the real ones, over each row's own transition, every
  length weighed alike (``models.inbetween.balanced``)."""
  z = spec.target_noise * jax.random.normal(key, (batch["window"].shape[0], spec.width))
  written, real = _predict(params, batch, z, spec)
  last, length = batch["window"][:, spec.context - 1 : spec.context], batch["length"]
  ext, before, upto = up_to_target(written, real, length)
  pose = balanced(jnp.abs(ext - real).mean(-1), before, length, spec.max_frames)
  steps = lambda x: jnp.diff(jnp.concatenate([last, x], 1), axis=1)
  step = balanced(jnp.abs(steps(ext) - steps(real)).mean(-1), upto, length, spec.max_frames)
  return pose + spec.velocity_weight * step, {"pose_l1": pose, "step_l1": step}


def _inbetween_train_step(state, batch, key, spec: InbetweenSpec | cvae.CvaeSpec):
  key = step_key(key, state["step"])
  if isinstance(spec, cvae.CvaeSpec):
    return cvae.cvae_step(state, batch, key, spec)
  (loss, aux), grads = jax.value_and_grad(transition_loss, has_aux=True)(state["params"], batch, key, spec)
  updates, opt_state = spec.tx.update(grads, state["opt_state"], state["params"])
  params = optax.apply_updates(state["params"], updates)
  metrics = {"loss": loss, **aux, "grad_norm": optax.tree.norm(grads), "lr": spec.schedule(state["step"])}
  return {"params": params, "opt_state": opt_state, "step": state["step"] + 1}, metrics


inbetween_train_step = functools.partial(jax.jit, static_argnums=3, donate_argnums=0)(_inbetween_train_step)
inbetween_train_step.__doc__ = """``inbetween_train_step(state, batch, key, spec) -> (state, metrics)``; ``state`` is
donated, ``spec`` (an :class:`InbetweenSpec`, or a ``cvae.CvaeSpec`` for the cvae system) is static."""


@functools.partial(jax.jit, static_argnums=2)
def validation_loss(params, batch, spec: InbetweenSpec | cvae.CvaeSpec):
  """The pose L1 of the held-out transitions in ``batch`` (no noise)."""
  if isinstance(spec, cvae.CvaeSpec):
    return cvae.cvae_validation(params, batch, spec)
  written, real = _predict(params, batch, jnp.zeros((batch["window"].shape[0], spec.width)), spec)
  return transition_l1(written, real[:, :-1], batch["length"])


# ---------------------------------------------------------------- writing transitions


@functools.partial(jax.jit, static_argnums=(0, 5))
def _transitions(graphdef, params, context_BxCxK, target_BxK, z_BxE, frames: int):
  length = jnp.full((context_BxCxK.shape[0],), frames, jnp.int32)
  return rollout(nnx.merge(graphdef, params), context_BxCxK, target_BxK, length, frames, z_BxE)


_cvae_transitions = jax.jit(cvae.cvae_transitions, static_argnums=(0, 4, 6))


def model_transitions(graphdef, params, ib, context_BxCxK, target_BxK, frames: int, key) -> np.ndarray:
  """A trained model's ``frames``-frame transitions ``[B, frames, K]`` (local flat poses; the last
  ``ib.context`` context frames are used). ``key`` draws each row's noise: the LSTM system's ``z_target``
  at ``ib.target_noise``; the cvae system's latents, ``mu + target_noise x sigma x eps``."""
  ctx = jnp.asarray(context_BxCxK)[:, -ib.context :]
  if ib.system == "cvae":
    out = _cvae_transitions(graphdef, params, ctx, jnp.asarray(target_BxK), frames, key, ib.target_noise)
    return np.asarray(out)
  z = ib.target_noise * jax.random.normal(key, (ctx.shape[0], ib.encoder_sizes[-1]))
  return np.asarray(_transitions(graphdef, params, ctx, jnp.asarray(target_BxK), z, frames))


def write_transitions(graphdef, params, f: Features, ib, context_CxJx3, targets, frames, key, num: int = 1):
  """``num`` pieces ``[num, C + sum(frames) + len(targets), J, 3]`` (data space): the context phrase, then
  for each target pose (``[J, 3]``) its transition of ``frames[i]`` frames and the target itself. Context
  and targets are copied in unchanged; each segment's context is the piece so far. ``f``, ``ib``: the
  run's features and ``[inbetween]`` config."""
  space = Space.of(f)
  piece = np.repeat(np.asarray(context_CxJx3, np.float32)[None], num, 0)
  for i, (target, n) in enumerate(zip(targets, frames)):
    canon = np.asarray(f.canonical(piece[:, -ib.context :]), np.float32)
    goal = np.asarray(f.canonical(np.asarray(target, np.float32)[None]), np.float32)
    anchor = space.anchor(canon[:, -1])
    ctx, tgt = space.to_local(canon, anchor), space.to_local(np.repeat(goal[None], num, 0), anchor)[:, 0]
    local = model_transitions(graphdef, params, ib, ctx, tgt, n, jax.random.fold_in(key, i))
    between = np.asarray(f.uncanonical(space.from_local(local, anchor)), np.float32)
    piece = np.concatenate([piece, between, np.repeat(np.asarray(target, np.float32)[None, None], num, 0)], 1)
  return piece


def end_sample(graphdef, params, ds, cfg: Config) -> tuple:
  """What a run ends with: ``(the real take, pieces [sample.num, T, J, 3], their title)``: the held-out
  take's first ``context`` frames (the take of ``sample.motion`` without one) and a key pose of it every
  ``min(max_frames, 30) + 1`` frames up to ``sample.frames`` (at least one), the model writing every frame
  between."""
  ib, s = cfg.inbetween, cfg.sample
  name = ds.val_names[0] if ds.val_names else ds.motions[s.motion].name
  take = next(m for m in ds.motions if m.name == name)
  seg = min(ib.max_frames, 30)
  upto = min(take.num_frames, ib.context + max(s.frames, seg + 1))  # at least one transition
  keys = list(range(ib.context - 1 + seg + 1, upto, seg + 1))
  pos = take.positions
  pieces = write_transitions(
    graphdef,
    params,
    ds.features,
    ib,
    pos[: ib.context],
    [pos[k] for k in keys],
    [seg] * len(keys),
    jax.random.key(s.seed),
    s.num,
  )
  real = take.replace(positions=pos[: pieces.shape[1]], name=f"original: {name}")
  return real, pieces, f"in-between, key poses of {name} every {seg + 1} frames"
