"""Training Tang et al. 2022's transition system (``inbetween.system = "cvae"``; networks in
``chorjax.models.cvae``). ``chorjax.inbetween`` dispatches here; batches, the local space, the loop,
checkpoints and the evaluation are the in-betweening family's.

One run trains both stages: steps ``0 .. manifold_steps`` the motion manifold, the rest the transition
sampler with the manifold frozen (its parameters pass through the step untouched: bit-identical). The
state is ``{params: {manifold, sampler}, opt_state: {manifold, sampler}, step}``; one jitted step holds
both stages (``lax.cond`` on the step), so resume is exact in either.

Stage 1 (per batch: ``manifold_frames`` frames after each window's context): L1 reconstruction + ``kl_weight``
x KL to N(0, I); scheduled sampling from the start (``p`` = step / ``sampling_ramp``, at most 1); from
``physics_start`` the foot-skating and bone-length losses join with a weight ramping from 0 to 1 over the
rest of stage 1, while the learning rate (cosine-decayed to ``optim.final_lr_ratio`` until then) warms
again from 0 to the peak (the paper: 1e-4 -> 1e-5, re-warmed). Stage 2: transitions of each row's own
length, written by the sampler through the frozen decoder, against the real frames: pose 1, steps
``velocity_weight``, legs 0.5, bones 0.5, feet (skating) 0.5 (the paper's weights for rotations/positions,
legs, bones and feet, on positions), each length weighed alike as for the LSTM system.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import optax
from flax import nnx

from chorjax.config import Config
from chorjax.families.inbetween.cvae_model import TransitionCVAE, manifold_rollout, sampler_rollout, transition_model
from chorjax.families.inbetween.lstm_model import balanced, transition_l1, up_to_target, window_target
from chorjax.optimizer import create_optimizer, update_part

LEGS, BONES, FEET = 0.5, 0.5, 0.5  # stage-2 loss weights beside the pose (1) and the steps (velocity_weight)
SKATE_HEIGHT = 0.1  # leg lengths above a window's lowest foot at which skating stops counting


@dataclasses.dataclass(frozen=True)
class CvaeSpec:
  """The static half of a CVAE train step (hashable)."""

  graphdef: Any
  manifold_def: Any
  tx_manifold: optax.GradientTransformation
  tx_sampler: optax.GradientTransformation
  schedule: optax.Schedule
  sampler_schedule: optax.Schedule
  context: int
  max_frames: int
  manifold_steps: int
  manifold_frames: int
  sampling_ramp: int
  physics_start: int
  kl_weight: float
  velocity_weight: float
  root: int
  feet: tuple
  legs: tuple  # the joints of both legs (feet up to, not including, the root)
  bones: tuple  # (parent, child, rest length in leg lengths)


def stage1_schedule(peak: float, final_ratio: float, physics_start: int, manifold_steps: int) -> optax.Schedule:
  """The manifold's learning rate: cosine from ``peak`` to ``peak x final_ratio`` until ``physics_start``,
  then linear from 0 back to ``peak`` at the end of stage 1."""
  decay = optax.cosine_decay_schedule(peak, max(physics_start, 1), alpha=final_ratio)
  warm = optax.linear_schedule(0.0, peak, max(manifold_steps - physics_start, 1))
  return optax.join_schedules([decay, warm], [physics_start])


def physics_ramp(step, spec: CvaeSpec):
  """The weight of stage 1's foot and bone losses: 0 before ``physics_start``, 1 at the end of stage 1."""
  return jnp.clip((step - spec.physics_start) / max(spec.manifold_steps - spec.physics_start, 1), 0.0, 1.0)


def own_frame_chance(step, spec: CvaeSpec):
  """Scheduled sampling's ``p``: the chance that stage 1 feeds the model its own previous frame."""
  return jnp.clip(step / spec.sampling_ramp, 0.0, 1.0)


def create_cvae_state(cfg: Config, features, space) -> tuple[dict, CvaeSpec]:
  ib, sk = cfg.inbetween, features.skeleton
  model = transition_model(cfg, features)
  assert isinstance(model, TransitionCVAE)
  graphdef, params = nnx.split(model, nnx.Param)
  manifold_def = nnx.split(model.manifold, nnx.Param)[0]
  params = nnx.to_pure_dict(params)
  o = cfg.optim
  schedule = stage1_schedule(o.lr, o.final_lr_ratio, ib.physics_start, ib.manifold_steps)
  tx_manifold, _ = create_optimizer(cfg, schedule=schedule)
  sampler_cfg = dataclasses.replace(
    cfg, train=dataclasses.replace(cfg.train, num_steps=cfg.train.num_steps - ib.manifold_steps)
  )
  tx_sampler, sampler_schedule = create_optimizer(sampler_cfg)
  legs = tuple(sorted({j for f in sk.feet for j in _chain(sk.parents, f) if j != sk.root}))
  bones = tuple((p, c, float(features.lengths[c]) / space.size) for p, c in sk.bones)
  spec = CvaeSpec(
    graphdef, manifold_def, tx_manifold, tx_sampler, schedule, sampler_schedule, ib.context, ib.max_frames,
    ib.manifold_steps, ib.manifold_frames, ib.sampling_ramp, ib.physics_start, ib.kl_weight, ib.velocity_weight,
    sk.root, tuple(sk.feet), legs, bones,
  )  # fmt: skip
  opt_state = {"manifold": tx_manifold.init(params["manifold"]), "sampler": tx_sampler.init(params["sampler"])}
  return {"params": params, "opt_state": opt_state, "step": jnp.zeros((), jnp.int32)}, spec


def _chain(parents, joint: int) -> list[int]:
  out = []
  while joint >= 0:
    out.append(joint)
    joint = parents[joint]
  return out


def _joints(x):
  return x.reshape(*x.shape[:-1], -1, 3)


def skate_loss(frames_BxTxK, feet, floor_B):
  """Horizontal foot steps weighted by nearness to the floor (differentiable; see ``metrics.foot_skate``)."""
  f = _joints(frames_BxTxK)[:, :, jnp.asarray(feet)]
  h = f[:, 1:, :, 1] - floor_B[:, None, None]
  weight = jnp.clip(2.0 - jnp.power(2.0, jnp.maximum(h, 0.0) / SKATE_HEIGHT), 0.0, 1.0)
  step = jnp.sqrt(jnp.sum(jnp.square(jnp.diff(f, axis=1)[..., jnp.array([0, 2])]), -1) + 1e-12)
  return (step * jax.lax.stop_gradient(weight)).mean(-1)  # [B, T - 1]


def bone_loss(frames_BxTxK, bones):
  """``[B, T]`` mean absolute difference of every bone's length from the training takes' mean length."""
  j = _joints(frames_BxTxK)
  parent, child = jnp.array([b[0] for b in bones]), jnp.array([b[1] for b in bones])
  length = jnp.sqrt(jnp.sum(jnp.square(j[..., child, :] - j[..., parent, :]), -1) + 1e-12)
  return jnp.abs(length - jnp.array([b[2] for b in bones])).mean(-1)


def manifold_loss(man_params, batch, key, step, spec: CvaeSpec):
  manifold = nnx.merge(spec.manifold_def, man_params)
  window, c, n = batch["window"], spec.context, spec.manifold_frames
  out, mu, logvar, weights = manifold_rollout(manifold, window, c, n, own_frame_chance(step, spec), key, spec.root)
  real = window[:, c : c + n]
  recon = jnp.abs(out - real).mean()
  kl = (0.5 * (jnp.exp(logvar) + mu**2 - 1.0 - logvar).sum(-1)).mean()
  floor = _joints(window)[:, :, jnp.asarray(spec.feet), 1].min(axis=(1, 2))
  with_prev = jnp.concatenate([window[:, c - 1 : c], out], 1)
  physics = skate_loss(with_prev, spec.feet, floor).mean() + bone_loss(out, spec.bones).mean()
  loss = recon + spec.kl_weight * kl + physics_ramp(step, spec) * physics
  usage = weights.mean(axis=(0, 1))
  return loss, {"recon": recon, "kl": kl, "physics": physics, "expert_max_share": usage.max()}


def sampler_loss(sampler_params, manifold_params, batch, key, spec: CvaeSpec, noise: float = 1.0):
  """Stage 2's loss: the transitions the sampler writes through the frozen manifold against the real ones."""
  model = nnx.merge(spec.graphdef, {"manifold": jax.lax.stop_gradient(manifold_params), "sampler": sampler_params})
  c, n = spec.context, spec.max_frames
  window, length = batch["window"], batch["length"]
  written, _, _ = sampler_rollout(model, window[:, :c], window_target(window, c, length), length, n, key, noise)
  real = window[:, c : c + n + 1]
  ext, inside, upto = up_to_target(written, real, length)
  weigh = lambda err, m: balanced(err, m, length, n)
  with_last = jnp.concatenate([window[:, c - 1 : c], ext], 1)
  steps = lambda x: jnp.diff(x, axis=1)
  legs = jnp.asarray(spec.legs)
  floor = _joints(window)[:, :, jnp.asarray(spec.feet), 1].min(axis=(1, 2))
  terms = {
    "pose_l1": weigh(jnp.abs(ext - real).mean(-1), inside),
    "step_l1": weigh(
      jnp.abs(steps(with_last) - steps(jnp.concatenate([window[:, c - 1 : c], real], 1))).mean(-1), upto
    ),
    "legs_l1": weigh(jnp.abs(_joints(ext)[:, :, legs] - _joints(real)[:, :, legs]).mean((-1, -2)), inside),
    "bones": weigh(bone_loss(ext, spec.bones), inside),
    "feet": weigh(skate_loss(with_last, spec.feet, floor), upto),
  }
  loss = terms["pose_l1"] + spec.velocity_weight * terms["step_l1"] + LEGS * terms["legs_l1"]
  return loss + BONES * terms["bones"] + FEET * terms["feet"], terms


STAGE1_KEYS = ("recon", "kl", "physics", "expert_max_share")
STAGE2_KEYS = ("pose_l1", "step_l1", "legs_l1", "bones", "feet")


def _stage1(state, batch, key, spec: CvaeSpec):
  step = state["step"]
  state, loss, aux, _ = update_part(state, "manifold", spec.tx_manifold, manifold_loss, batch, key, step, spec)
  lr = jnp.asarray(spec.schedule(step), jnp.float32)
  metrics = {"loss": loss, **aux, **{k: jnp.zeros(()) for k in STAGE2_KEYS}, "lr": lr}
  return state, {**metrics, "p_own": own_frame_chance(step, spec), "physics_weight": physics_ramp(step, spec)}


def _stage2(state, batch, key, spec: CvaeSpec):
  manifold = state["params"]["manifold"]
  state, loss, aux, _ = update_part(state, "sampler", spec.tx_sampler, sampler_loss, manifold, batch, key, spec)
  lr = spec.sampler_schedule(state["step"] - spec.manifold_steps)
  metrics = {"loss": loss, **{k: jnp.zeros(()) for k in STAGE1_KEYS}, **aux, "lr": jnp.asarray(lr, jnp.float32)}
  return state, {**metrics, "p_own": jnp.ones(()), "physics_weight": jnp.ones(())}


def cvae_step(state, batch, key, spec: CvaeSpec):
  """One step of stage 1 (``step < manifold_steps``) or stage 2: ``(state, metrics)``; ``key`` is the step's."""
  first = state["step"] < spec.manifold_steps
  stage1 = lambda s, b, k: _stage1(s, b, k, spec)
  stage2 = lambda s, b, k: _stage2(s, b, k, spec)
  state, metrics = jax.lax.cond(first, stage1, stage2, state, batch, key)
  return {**state, "step": state["step"] + 1}, metrics


def cvae_validation(params, batch, spec: CvaeSpec):
  """The pose L1 of held-out transitions written by the sampler (its mean latents)."""
  model = nnx.merge(spec.graphdef, params)
  c, n = spec.context, spec.max_frames
  window, length = batch["window"], batch["length"]
  target = window_target(window, c, length)
  written, _, _ = sampler_rollout(model, window[:, :c], target, length, n, jax.random.key(0), 0.0)
  return transition_l1(written, window[:, c : c + n], length)


def cvae_transitions(graphdef, params, context_BxCxK, target_BxK, frames: int, key, noise: float):
  length = jnp.full((context_BxCxK.shape[0],), frames, jnp.int32)
  return sampler_rollout(nnx.merge(graphdef, params), context_BxCxK, target_BxK, length, frames, key, noise)[0]
