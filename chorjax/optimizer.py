"""The optimizer every family trains with (``[optim]``), one update of a part of the parameters, and the
train step's PRNG key."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import optax

from chorjax.config import Config


def create_optimizer(
  cfg: Config, lr: float | None = None, schedule: optax.Schedule | None = None
) -> tuple[optax.GradientTransformation, optax.Schedule]:
  """The optax chain of ``cfg.optim``: optional global-norm clipping, then the optimizer; ``lr``: the peak
  learning rate instead of ``optim.lr`` (the GAN family's two networks); ``schedule``: a learning-rate
  schedule instead of ``optim.schedule``'s (the cvae system's stage 1)."""
  o = cfg.optim
  peak = o.lr if lr is None else lr
  if schedule is None and o.schedule == "warmup_cosine":
    schedule = optax.warmup_cosine_decay_schedule(
      0.0, peak, o.warmup_steps, max(cfg.train.num_steps, o.warmup_steps + 1), end_value=peak * o.final_lr_ratio
    )
  elif schedule is None:
    schedule = optax.constant_schedule(peak)
  if o.name == "adam":
    opt = optax.adam(schedule, b1=o.b1, b2=o.b2)
  elif o.name == "adamw":
    opt = optax.adamw(schedule, b1=o.b1, b2=o.b2, weight_decay=o.weight_decay, mask=_decayed)
  else:
    opt = optax.amsgrad(schedule, b1=o.b1, b2=o.b2)
  chain = [optax.clip_by_global_norm(o.clip_norm)] if o.clip_norm > 0 else []
  return optax.chain(*chain, opt), schedule


def _decayed(params):
  """Weight decay's mask: every parameter but a fixed basis (``model.mdn_basis``), which is never trained."""
  is_basis = lambda path: any(getattr(k, "key", None) == "basis" for k in path)
  return jax.tree_util.tree_map_with_path(lambda path, _: not is_basis(path), params)


def update_part(state, part: str, tx, loss_fn, *args):
  """One optimizer step on ``state["params"][part]`` alone (a GAN's critic, a CVAE's sampler, ...):
  ``loss_fn(part_params, *args) -> (loss, aux)`` is differentiated and ``tx`` updates that part and its
  optimizer state; the other parts pass through. ``(state, loss, aux, grads)``; the step count is the caller's."""
  params, opt = state["params"], state["opt_state"]
  (loss, aux), grads = jax.value_and_grad(loss_fn, has_aux=True)(params[part], *args)
  updates, part_opt = tx.update(grads, opt[part], params[part])
  new = optax.apply_updates(params[part], updates)
  return {**state, "params": {**params, part: new}, "opt_state": {**opt, part: part_opt}}, loss, aux, grads


def step_key(key, step):
  """The train step's PRNG key: ``key`` (a typed key, or raw uint32 key data replicated across processes)
  folded with ``step``, so a resumed run draws what the uninterrupted one drew."""
  if not jnp.issubdtype(key.dtype, jax.dtypes.prng_key):
    key = jax.random.wrap_key_data(key)
  return jax.random.fold_in(key, step)
