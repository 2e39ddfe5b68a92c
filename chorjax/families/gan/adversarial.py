"""Training the LSTM-GAN family (``model.family = "gan"``): its state, the critic and generator steps, and
the jitted train step that the training loop runs.

The state is ``{params: {generator, critic}, opt_state: {generator, critic}, step}``: one checkpoint,
one exact resume, as for the other families. One train step makes ``gan.critic_steps`` critic updates,
each on its own real batch (the batch holds ``batch_size x critic_steps`` windows of ``data.seq_length``
frames), then one generator update against the critic as it now is (frozen: the generator's loss has
the critic's parameters as constants). Generated sequences enter the critic's loss under
``stop_gradient``, and each update touches only its own half of the parameters.

Losses (``gan.loss``): ``bce``, the tutorial's binary cross-entropy (the critic a classifier with a
sigmoid output; the non-saturating generator loss ``-log D(G(z))``), or ``wgan-gp`` (Gulrajani et al.
2017: the critic's score difference plus ``gp_weight`` x the penalty on its gradient norm at points
between real and generated sequences; the generator loss ``-D(G(z))``).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

import jax
import jax.numpy as jnp
import optax
from flax import nnx

from chorjax.config import Config
from chorjax.errors import UserError
from chorjax.families.gan.networks import GanModel, fake_sequences, pose_layer
from chorjax.optimizer import create_optimizer, step_key, update_part


@dataclasses.dataclass(frozen=True)
class GanSpec:
  """What the GAN train step needs besides its arrays (hashable: a static jit argument).

  Attributes:
    graphdef: the whole model's static graph (``{generator, critic}`` params; sampling, checkpoints).
    generator_def, critic_def: the two networks' static graphs.
    tx_generator, tx_critic: their optimizers; schedule: the generator's learning rate by step (logged).
    loss, gp_weight, critic_steps: ``gan.*``.
    projection: the generator's output -> the features (``models.gan.pose_layer`` of ``gan.pose``), or None.
  """

  graphdef: Any
  generator_def: Any
  critic_def: Any
  tx_generator: optax.GradientTransformation
  tx_critic: optax.GradientTransformation
  schedule: optax.Schedule
  loss: str
  gp_weight: float
  critic_steps: int
  projection: Any


def check_gan(cfg: Config, representation: str) -> None:
  """Raises UserError, naming the key, for a GAN config that cannot train (checked before any work)."""
  g = cfg.gan
  for key in ("generator_dense", "critic_dense"):
    sizes = getattr(g, key)
    if not all(isinstance(v, int) and v > 0 for v in sizes):
      raise UserError(f"gan.{key}: expected a list of positive layer sizes, got {list(sizes)}")
  if g.pose != "features" and representation != "directions":
    raise UserError(
      f"gan.pose = {g.pose!r} needs data.representation = 'directions' (this config: {representation!r}); "
      "or set gan.pose = 'features'"
    )
  if cfg.train.feedback != "none":
    raise UserError("train.feedback: the GAN family draws whole sequences; set train.feedback = 'none'")


def create_gan_state(cfg: Config, features) -> tuple[dict, GanSpec]:
  """``({params, opt_state, step}, spec)`` for a fresh GAN run on ``features`` (the run's ``Features``)."""
  check_gan(cfg, features.representation)
  model = GanModel(cfg.gan, features.dim, rngs=nnx.Rngs(cfg.train.seed))
  graphdef = nnx.split(model, nnx.Param)[0]
  gen_def, gen = nnx.split(model.generator, nnx.Param)
  critic_def, critic = nnx.split(model.critic, nnx.Param)
  params = {"generator": nnx.to_pure_dict(gen), "critic": nnx.to_pure_dict(critic)}
  tx_g, schedule = create_optimizer(cfg, lr=cfg.gan.generator_lr)
  tx_c, _ = create_optimizer(cfg, lr=cfg.gan.critic_lr)
  opt_state = {"generator": tx_g.init(params["generator"]), "critic": tx_c.init(params["critic"])}
  projection = pose_layer(features, cfg.gan.pose)
  g = cfg.gan
  spec = GanSpec(graphdef, gen_def, critic_def, tx_g, tx_c, schedule, g.loss, g.gp_weight, g.critic_steps, projection)
  return {"params": params, "opt_state": opt_state, "step": jnp.zeros((), jnp.int32)}, spec


def _fake(spec: GanSpec, gen_params, key, num: int, frames: int):
  return fake_sequences(nnx.merge(spec.generator_def, gen_params), key, num, frames, spec.projection)


def critic_loss(critic_params, gen_params, real_BxTxD, key, spec: GanSpec):
  """The critic's loss on a real batch and as many generated sequences: ``(loss, aux metrics)``."""
  critic = nnx.merge(spec.critic_def, critic_params)
  b, t, _ = real_BxTxD.shape
  k_fake, k_mix = jax.random.split(key)
  fake = jax.lax.stop_gradient(_fake(spec, gen_params, k_fake, b, t))
  d_real, d_fake = critic(real_BxTxD), critic(fake)
  if spec.loss == "bce":
    loss = (
      optax.sigmoid_binary_cross_entropy(d_real, 1.0).mean() + optax.sigmoid_binary_cross_entropy(d_fake, 0.0).mean()
    )
    return loss, {"d_real": jax.nn.sigmoid(d_real).mean(), "d_fake": jax.nn.sigmoid(d_fake).mean()}
  eps = jax.random.uniform(k_mix, (b, 1, 1))
  between = eps * real_BxTxD + (1.0 - eps) * fake
  grad = jax.grad(lambda x: critic(x).sum())(between)
  penalty = jnp.square(jnp.sqrt(jnp.sum(grad * grad, axis=(1, 2)) + 1e-12) - 1.0).mean()
  distance = d_real.mean() - d_fake.mean()
  return -distance + spec.gp_weight * penalty, {"wasserstein": distance, "gradient_penalty": penalty}


def generator_loss(gen_params, critic_params, key, num: int, frames: int, spec: GanSpec):
  """The generator's loss against the critic (whose parameters are constants here)."""
  d_fake = nnx.merge(spec.critic_def, critic_params)(_fake(spec, gen_params, key, num, frames))
  if spec.loss == "bce":
    return optax.sigmoid_binary_cross_entropy(d_fake, 1.0).mean()
  return -d_fake.mean()


def critic_step(state, real_BxTxD, key, spec: GanSpec):
  """One critic update: ``(state, metrics)``; the generator's parameters and optimizer state pass through."""
  gen = state["params"]["generator"]
  state, loss, aux, grads = update_part(state, "critic", spec.tx_critic, critic_loss, gen, real_BxTxD, key, spec)
  return state, {"critic_loss": loss, **aux, "critic_grad_norm": optax.tree.norm(grads)}


def generator_step(state, key, num: int, frames: int, spec: GanSpec):
  """One generator update against the frozen critic: ``(state, metrics)``; the critic passes through."""
  with_aux = lambda *args: (generator_loss(*args), None)
  critic = state["params"]["critic"]
  state, loss, _, grads = update_part(state, "generator", spec.tx_generator, with_aux, critic, key, num, frames, spec)
  return state, {"gen_loss": loss, "gen_grad_norm": optax.tree.norm(grads)}


def _gan_train_step(state, batch, key, spec: GanSpec):
  """``critic_steps`` critic updates (one per slice of the batch), then one generator update. ``metrics``:
  ``loss`` (= ``gen_loss``, what the loop checks and logs as train_loss), ``gen_loss``, ``critic_loss``
  (the last critic update's) and the loss's own terms."""
  key = step_key(key, state["step"])
  real = batch["inputs"]
  n = spec.critic_steps
  real_NxBxTxD = real.reshape(n, real.shape[0] // n, *real.shape[1:])
  k_critic, k_gen = jax.random.split(key)
  state, critic_metrics = jax.lax.scan(
    lambda s, xs: critic_step(s, xs[0], xs[1], spec), state, (real_NxBxTxD, jax.random.split(k_critic, n))
  )
  b, t = real_NxBxTxD.shape[1:3]
  state, gen_metrics = generator_step(state, k_gen, b, t, spec)
  metrics = {
    "loss": gen_metrics["gen_loss"],
    **gen_metrics,
    **{k: v[-1] for k, v in critic_metrics.items()},
    "lr": spec.schedule(state["step"]),
  }
  return {**state, "step": state["step"] + 1}, metrics


gan_train_step = functools.partial(jax.jit, static_argnums=3, donate_argnums=0)(_gan_train_step)
gan_train_step.__doc__ = """``gan_train_step(state, batch, key, spec) -> (state, metrics)``; ``state`` is donated."""
