"""The recurrent family's training: its state and static spec, the teacher-forced loss (and the loss with
its own outputs fed back, ``train.feedback``), the jitted train and evaluation steps.

The state is a plain pytree ``{params, opt_state, step}``. Randomness comes from
``fold_in(key(seed), step)`` (``optimizer.step_key``), so a run resumed at step s repeats exactly what the
uninterrupted run did after s.
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
from chorjax.families.recurrent.recurrent_model import create_model
from chorjax.models.heads import frame_numbers
from chorjax.optimizer import create_optimizer, step_key
from chorjax.runtime import side_by_side


@dataclasses.dataclass(frozen=True)
class Feedback:
  """How training feeds the model's own outputs back as inputs (see ``train.feedback``)."""

  mode: str  # "auto" or "scheduled"
  ground_truth_frames: int
  condition_frames: int
  max_fraction: float
  warmup: int
  ramp: int
  draw: str  # "sample" or "mean"
  pi_temperature: float
  sigma_temperature: float

  @classmethod
  def of(cls, cfg: Config) -> Feedback | None:
    t = cfg.train
    if t.feedback == "none":
      return None
    return cls(
      t.feedback,
      t.ground_truth_frames,
      t.condition_frames,
      t.feedback_max,
      t.feedback_warmup,
      t.feedback_ramp,
      t.feedback_draw,
      cfg.sample.pi_temperature,
      cfg.sample.sigma_temperature,
    )


@dataclasses.dataclass(frozen=True)
class StepSpec:
  """What the train step needs besides its arrays; hashable, so it is a static jit argument.

  Attributes:
    graphdef: the model's static graph (``nnx.split``).
    tx: the optax optimizer chain.
    schedule: learning rate as a function of the step (logged).
    input_noise: std of Gaussian noise added to the inputs (normalized units).
    dropout: the model's dropout rate (0 = no dropout key is drawn).
    feedback: own outputs fed back as inputs (None = teacher forcing only).
    parts: the batch's equal shares (``train.batch_parts``), each with its own key; their gradients' mean
      makes the update.
  """

  graphdef: Any
  tx: optax.GradientTransformation
  schedule: optax.Schedule
  input_noise: float
  dropout: float
  feedback: Feedback | None = None
  parts: int = 1


def create_train_state(cfg: Config, dim: int, num_motions: int, basis=None, white: int = 0) -> tuple[dict, StepSpec]:
  """``({params, opt_state, step}, spec)`` for a fresh run of ``cfg`` (the rnn family) on ``dim`` features;
  ``basis``: the MDN's ``[D, D]`` coordinates where ``model.mdn_basis`` is not "features"
  (``families.recurrent.mdn_basis``); ``white``: its last coordinates that carry no residuals."""
  model = create_model(cfg.model, dim, num_motions, cfg.train.seed, white)
  graphdef, params = nnx.split(model, nnx.Param)
  params = nnx.to_pure_dict(params)
  if cfg.model.pca_basis:
    if basis is None or np.shape(basis) != (dim, dim):
      raise ValueError(
        f"model.mdn_basis = {cfg.model.mdn_basis!r} needs a [{dim}, {dim}] basis, "
        f"got {basis if basis is None else np.shape(basis)}"
      )
    params["head"]["basis"] = jnp.asarray(basis, jnp.float32)
  tx, schedule = create_optimizer(cfg)
  state = {"params": params, "opt_state": tx.init(params), "step": jnp.zeros((), jnp.int32)}
  t = cfg.train
  return state, StepSpec(graphdef, tx, schedule, t.input_noise, cfg.model.dropout, Feedback.of(cfg), t.batch_parts)


def _loss_fn(params, batch, key, spec: StepSpec, noise=None):
  """The teacher-forced loss; ``noise``: the input noise as a traced value (vectorized training,
  where points differ in it), else ``spec.input_noise``."""
  model = nnx.merge(spec.graphdef, params)
  x = batch["inputs"]
  noise_key, dropout_key = jax.random.split(key)
  if noise is not None:
    x = x + noise * jax.random.normal(noise_key, x.shape, x.dtype)
  elif spec.input_noise > 0:
    x = x + spec.input_noise * jax.random.normal(noise_key, x.shape, x.dtype)
  out = model(x, batch["motion_ids"], dropout_key if spec.dropout > 0 else None)
  return model.loss(out, batch["targets"])


def feedback_mask(fb: Feedback, key, step, batch: int, frames: int):
  """``[B, T]`` True where input frame t is the model's own output (never t = 0).

  The schedule ramps from 0 to 1 over ``fb.ramp`` steps after ``fb.warmup``. Auto-conditioning
  feeds ``condition_frames`` own frames after every ``ground_truth_frames`` real ones, in a sequence
  chosen with the schedule's probability; scheduled sampling feeds each frame with probability
  ``max_fraction`` x the schedule.
  """
  after = (step - fb.warmup + 1).astype(jnp.float32)
  ramp = jnp.clip(after / fb.ramp, 0.0, 1.0) if fb.ramp > 0 else (after > 0).astype(jnp.float32)
  t = jnp.arange(frames)
  if fb.mode == "auto":
    own = (t % (fb.ground_truth_frames + fb.condition_frames)) >= fb.ground_truth_frames
    chosen = jax.random.uniform(key, (batch, 1)) < ramp
    mask = own[None] & chosen
  else:
    mask = jax.random.uniform(key, (batch, frames)) < fb.max_fraction * ramp
  return mask & (t > 0)[None]


def _feedback_loss_fn(params, batch, key, step, spec: StepSpec):
  """The loss with the model's own outputs fed back as inputs where ``feedback_mask`` says.

  The window runs frame by frame (``model.step``), since an input may be the previous output. What is
  fed back is a draw at the run's sample temperatures (as generation feeds itself) or the mixture
  mean, under ``stop_gradient``: a draw has no gradient, and the gradient through hundreds of fed-back
  frames would be that of a much deeper, unstable network. Dropout drops the units the whole-window call
  would with the same key (one mask per window and layer). A model that carries residuals
  (``model.mdn_memory``) draws each own frame carrying the residuals of the frames it was fed, its own or real,
  as generation does; its loss carries the targets' (the likelihood teacher forcing has). Carrying the own
  frames' residuals into the loss as well taught the carry nothing (a real frame owes nothing to an own draw's
  noise): on the labelled library, at step 1,500 its held-out loss was -147 against -275 and its own draw
  trembled at 12x the takes' jitter.
  """
  assert spec.feedback is not None
  fb, model = spec.feedback, nnx.merge(spec.graphdef, params)
  x_BxTxD = batch["inputs"]
  noise_key, mask_key, draw_key = jax.random.split(key, 3)
  if spec.input_noise > 0:
    x_BxTxD = x_BxTxD + spec.input_noise * jax.random.normal(noise_key, x_BxTxD.shape, x_BxTxD.dtype)
  b, t, _ = x_BxTxD.shape
  mask_BxT = feedback_mask(fb, mask_key, step, b, t)
  masks = model.core.dropout_masks(jax.random.split(key)[1], b) if spec.dropout > 0 else None  # _loss_fn's key

  def body(c, inputs):
    carry, prev_BxP, state = c
    x_BxD, own_B, first, k = inputs
    drawn = _own_frame(model, fb, prev_BxP, k, state)
    x_in = jnp.where(own_B[:, None], jax.lax.stop_gradient(drawn), x_BxD)
    if model.remembers:  # the residual of the frame fed, none before the window's first
      head = model.head
      state = head.remember(state, jnp.where(first, 0.0, head.residual(prev_BxP, head.to_basis(x_in))))
    carry, out_BxP = model.step(carry, x_in, masks)
    return (carry, out_BxP, state), out_BxP

  init = (
    model.initial_carry(batch["motion_ids"]),
    jnp.zeros((b, model.num_outputs), x_BxTxD.dtype),
    model.draw_start(x_BxTxD[:, :1]),
  )
  xs = (jnp.swapaxes(x_BxTxD, 0, 1), mask_BxT.T, jnp.arange(t) == 0, jax.random.split(draw_key, t))
  _, out_TxBxP = jax.lax.scan(body, init, xs)
  loss, aux = model.loss(jnp.swapaxes(out_TxBxP, 0, 1), batch["targets"])
  return loss, {**aux, "feedback": mask_BxT.mean()}


def _own_frame(model, fb: Feedback, prev_BxP, key, state):
  """The frame the model would feed itself after ``prev``: a draw at the feedback's temperatures carrying
  ``state``'s residuals (``model.draw``; its state is left to the caller, who carries the frame actually fed),
  or the mixture mean."""
  if fb.draw == "mean":
    return model.mean(prev_BxP)
  if not model.remembers:
    return model.sample(prev_BxP, key, fb.pi_temperature, fb.sigma_temperature)
  gumbel, noise = frame_numbers(key, prev_BxP.shape[0], model.num_mixtures, model.head.dim)
  drawn, _ = model.draw(
    prev_BxP, gumbel, noise, state, pi_temperature=fb.pi_temperature, sigma_temperature=fb.sigma_temperature
  )
  return drawn


def _train_step(state, batch, key, spec: StepSpec, lr_scale=None, noise=None):
  """One optimizer step. ``lr_scale`` and ``noise`` (traced; vectorized training, see
  ``chorjax.training.vectorized``): the update scaled by ``lr_scale``, the input noise ``noise`` instead of
  ``spec.input_noise``."""
  key = step_key(key, state["step"])
  (loss, aux), grads = _gradients(state["params"], batch, key, state["step"], spec, noise)
  return _update(state, loss, aux, grads, spec, lr_scale)


def _gradients(params, batch, key, step, spec: StepSpec, noise=None):
  """``((loss, aux), gradients)`` of ``batch`` at ``step`` (``key``: the step's); with ``spec.parts`` shares,
  the mean of theirs, one share after another (the program vectorized training vmaps; a lone run computes
  its shares side by side in threads instead, ``parted_train_step``: unvmapped, the same bits)."""
  if spec.parts > 1:
    shares = [_share(batch, key, i, spec.parts) for i in range(spec.parts)]
    return _mean_of_shares([_batch_gradients(params, part, k, step, spec, noise) for part, k in shares])
  return _batch_gradients(params, batch, key, step, spec, noise)


def _batch_gradients(params, batch, key, step, spec: StepSpec, noise=None):
  """``((loss, aux), gradients)`` of ``batch`` as one share."""
  if spec.feedback is None:  # teacher forcing: the fused layers over whole windows
    return jax.value_and_grad(_loss_fn, has_aux=True)(params, batch, key, spec, noise)
  return jax.value_and_grad(_feedback_loss_fn, has_aux=True)(params, batch, key, step, spec)


def _update(state, loss, aux, grads, spec: StepSpec, lr_scale=None):
  """The optimizer's step with ``grads``: ``(state, metrics)``."""
  updates, opt_state = spec.tx.update(grads, state["opt_state"], state["params"])
  if lr_scale is not None:
    updates = jax.tree.map(lambda u: u * lr_scale.astype(u.dtype), updates)
  params = optax.apply_updates(state["params"], updates)
  metrics = {
    "loss": loss,
    **aux,
    "grad_norm": optax.tree.norm(grads),
    "param_norm": optax.tree.norm(params),
    "update_norm": optax.tree.norm(updates),
    "lr": spec.schedule(state["step"]) * (1.0 if lr_scale is None else lr_scale),
  }
  return {"params": params, "opt_state": opt_state, "step": state["step"] + 1}, metrics


train_step = functools.partial(jax.jit, static_argnums=3, donate_argnums=0)(_train_step)
train_step.__doc__ = """``train_step(state, batch, key, spec) -> (state, metrics)``; ``state`` is donated,
``spec`` (a :class:`chorjax.run.StepSpec`) is static."""


def _share(batch, key, share: int, parts: int):
  """Share ``share`` of ``parts`` equal shares of ``batch``'s windows and its key (``key``: the step's)."""
  rows = len(batch["inputs"]) // parts
  return {k: v[share * rows : (share + 1) * rows] for k, v in batch.items()}, jax.random.split(key, parts)[share]


def _mean_of_shares(shares):
  """``((loss, aux), gradients)`` of a batch from its equal shares': their mean (a ``min_`` metric: their
  least)."""
  mean = lambda *xs: sum(xs) / len(xs)
  least = lambda *xs: functools.reduce(jnp.minimum, xs)
  losses, auxes, grads = [p[0][0] for p in shares], [p[0][1] for p in shares], [p[1] for p in shares]
  aux = {k: (least if k.startswith("min_") else mean)(*(a[k] for a in auxes)) for k in auxes[0]}
  return (mean(*losses), aux), jax.tree.map(mean, *grads)


@functools.partial(jax.jit, static_argnums=(4, 5))
def _share_gradients(params, batch, key, step, spec: StepSpec, share: int):
  """``_batch_gradients`` of share ``share`` of ``spec.parts`` (the batch's cut and the keys' split inside the
  program: a step dispatches one program per share and the update, no small operations between them)."""
  part, share_key = _share(batch, step_key(key, step), share, spec.parts)
  return _batch_gradients(params, part, share_key, step, spec)


@functools.partial(jax.jit, static_argnums=2, donate_argnums=0)
def _update_with_parts(state, shares, spec: StepSpec):
  """The update with ``shares`` (``((loss, aux), gradients)`` of a batch's equal shares): their mean."""
  (loss, aux), grads = _mean_of_shares(shares)
  return _update(state, loss, aux, grads, spec)


def parted_train_step(state, batch, key, spec: StepSpec):
  """``train_step`` with each batch in ``spec.parts`` equal shares of its windows (``train.batch_parts``), their
  gradients computed side by side in threads (one program each: on a CPU each share's time loops run on
  a core of their own, where one program runs a loop's small kernels one after another), then one update
  with their mean. The same loss in exact arithmetic; each share draws its own noise and dropout."""
  params, at = state["params"], state["step"]
  share = lambda i: jax.block_until_ready(_share_gradients(params, batch, key, at, spec, i))
  return _update_with_parts(state, list(side_by_side(share, range(spec.parts), at_once=spec.parts)), spec)


def sharded_train_step(parallel):
  """``train_step`` for a data-parallel run: the batch sharded over the mesh's data axis, the rest
  replicated."""
  repl, data = parallel.replicated, parallel.batch_sharding
  return jax.jit(
    _train_step, static_argnums=3, donate_argnums=0, in_shardings=(repl, data, repl), out_shardings=(repl, repl)
  )


@functools.partial(jax.jit, static_argnums=2)
def eval_step(params, batch, graphdef):
  """The model's loss on ``batch`` (no noise, no dropout)."""
  model = nnx.merge(graphdef, params)
  return model.loss(model(batch["inputs"], batch["motion_ids"]), batch["targets"])[0]
