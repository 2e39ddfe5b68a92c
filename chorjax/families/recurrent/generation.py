"""The recurrent family's draw: one jit-compiled ``lax.scan`` over frames, K dancers as a batch.

The model's own ``step`` (the same cell code that training scans) consumes the previous frame and
the head draws the next one. Priming runs the model teacher-forced over a real phrase and continues
from its state: chor-rnn's collaboration mode. Results go back to data space through the exact
inverse of the feature pipeline (:func:`dance`); live mode continues an endless dance chunk by chunk
(:func:`start_stream`, :func:`continue_stream`).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from flax import nnx

from chorjax.data.features import joint_pace
from chorjax.families.family import frame_io
from chorjax.models.heads import frame_numbers
from chorjax.sampling.controls import Controls, Draw, Pacing, noise_gain
from chorjax.sampling.table import MAX_NOISE_ORDER

# Frames per iteration of the plain generation loop, for long batched draws (at least UNROLL_FROM frames over
# the batch): an iteration's fixed cost (the loop's bookkeeping, one dispatch per operation) then serves four
# frames, 6-8% faster for the 3 x 256 LSTM at batch 64 over 1,000 frames (benchmarks.sampling_ceiling); the
# frames agree within 1.2e-7 (to the bit there, not always at batch 4). Shorter draws run one frame per
# iteration: the unrolled program takes 0.5 s longer to compile (1.25 s against 0.76 s for the quick start's
# 2 x 192 model), more than it saves below ~100,000 frames at batch 1, and at 2 x 192 it was no faster even at
# batch 64. The smoothed loop stays at one: no faster there (batch 1-4), and unrolled its rounding differs,
# which a free-running dance grows into another dance.
UNROLL = 4
UNROLL_FROM = 64 * 1000


def generate(graphdef, params, motion, key, *, num_frames: int, draw: Draw | None = None, prime_BxPxD=None):
  """Generates ``num_frames`` normalized frames per dancer.

  Args:
    graphdef: the model's static graph (``nnx.split``).
    params: the model parameters (an argument, not a closure, so the program stays small).
    motion: per dancer, what conditions it: motion ids ``[B]`` or weights ``[B, M]`` (a blend).
    key: PRNG key; the same key gives the same dance.
    num_frames: frames to generate after the prime.
    draw: the draw's controls (``Controls.draw``; default: full temperature, white noise, nothing held):
      the MDN temperatures and ``greedy`` (``heads.mdn_sample``); the noise through ``noise_order`` cascaded
      AR(1) filters with coefficient ``noise_smoothing`` (:func:`smooth_noise`); ``persistence`` added to the
      log-weight of the previous frame's component; ``crossfade``, the factor by which the jump between the
      means of a new and an old component decays per frame; ``bounds`` every drawn frame (and its change)
      is clipped to; the pace governor (``pace``, ``pace_lag``, ``pacing``: :func:`_smooth_scan`); the
      ceiling ``scale_cap`` ``[S]`` on the MDN scales.
    prime_BxPxD: optional real phrase (normalized); generation continues after its last frame.
      Without it, generation starts from the zero frame (the mean pose) and the id's state.

  Returns:
    ``[B, num_frames, D]`` normalized frames.
  """
  draw = (draw or Draw()).for_motion(motion)
  unroll = UNROLL if num_frames * np.shape(motion)[0] >= UNROLL_FROM else 1
  return _generate(
    graphdef,
    params,
    motion,
    key,
    draw,
    num_frames=num_frames,
    prime_BxPxD=prime_BxPxD,
    plain=draw.plain,
    unroll=unroll,
  )


@functools.partial(jax.jit, static_argnames=("graphdef", "num_frames", "plain", "unroll"))
def _generate(
  graphdef,
  params,
  motion,
  key,
  draw: Draw,
  *,
  num_frames: int,
  prime_BxPxD=None,
  plain: bool = True,
  unroll: int = 1,
):
  """:func:`generate`'s program; ``plain``: ``draw.plain`` (decided before tracing, where persistence and
  crossfade are still numbers); ``unroll``: frames per iteration of the plain loop (frames within 1.2e-7 either way).
  ``draw``'s static fields are part of what the program is compiled for."""
  model = nnx.merge(graphdef, params)
  carry, x0, before = _primed(model, motion, prime_BxPxD)

  if plain and not getattr(model, "remembers", False):  # a draw that carries residuals keeps its state
    bounds = draw.bounds

    def body(c, k):
      carry, previous = c
      carry, out = model.step(carry, previous)
      x = model.sample(out, k, draw.pi_temperature, draw.sigma_temperature, draw.greedy)
      x = x if bounds is None else bounds.clip(x, previous)
      return (carry, x), x

    _, xs_NxBxD = jax.lax.scan(body, (carry, x0), jax.random.split(key, num_frames), unroll=unroll)
    return jnp.swapaxes(xs_NxBxD, 0, 1)

  if draw.pace and draw.pacing is None:
    raise ValueError("pace needs draw.pacing (the training pace and its measure): Controls.draw")
  state = _smooth_start(carry, x0, draw, model.draw_start(*before))
  return _smooth_scan(model, state, key, num_frames, draw)[1]


def _primed(model, motion, prime_BxPxD):
  """``(carry, first input, (frames so far, the outputs that predicted them)))``: the motion's initial state,
  teacher forced over the prime if there is one (generation continues after its last frame; the head's draw
  state starts from the prime's residuals: ``model.draw_start(*before)``); without one, the zero frame (the
  mean pose) and no outputs."""
  carry = model.initial_carry(motion)
  if prime_BxPxD is None:
    x0 = jnp.zeros((jnp.shape(motion)[0], model.dim), jnp.float32)
    return carry, x0, (x0[:, None], None)
  out_BxPxP, carry = model.teacher_force(prime_BxPxD[:, :-1], carry)
  return carry, prime_BxPxD[:, -1], (prime_BxPxD, out_BxPxP)


def _smooth_start(carry, x0_BxD, draw: Draw, drawn):
  """The state of :func:`_smooth_scan` before the first frame: ``(carry, previous frame, noise filters
  [MAX_NOISE_ORDER, B, D], the head's draw state ``drawn`` (``model.draw_start``: component, offset,
  residuals), (the governor's recent frames, where the next goes, own pace))``."""
  b = x0_BxD.shape[0]
  pacing = draw.pacing if draw.pace else None
  lag, ref = (draw.pace_lag, pacing.ref) if pacing is not None else (1, 1.0)
  at = jnp.zeros((), jnp.int32)  # an array from the start: a resumed state keeps its type (no retrace)
  governor = (jnp.broadcast_to(x0_BxD, (lag, *x0_BxD.shape)), at, jnp.full((b,), ref, jnp.float32))
  filters = jnp.zeros((MAX_NOISE_ORDER, *x0_BxD.shape), x0_BxD.dtype)
  return (carry, x0_BxD, filters, drawn, governor)


def _smooth_scan(model, state, key, num_frames: int, draw: Draw):
  """``num_frames`` draws from ``state`` with smoothed noise and the draw's state (component, offset) carried:
  ``(the state after them, frames [B, N, D])``.

  With a governor (``draw.pace``, ``draw.pacing``) the dancer is held to the training pace ``pacing.ref``:
  how far it moves over ``pace_lag`` frames (:func:`_moved`; its own pace a running mean over about ten
  lags); off pace, the scale temperature rises or falls and the component is let go sooner (:func:`_governed`)."""
  step = frame_step(model, draw)
  b, d = state[1].shape

  def body(c, k):
    return step(c, *frame_numbers(k, b, model.num_mixtures, d))

  state, xs_NxBxD = jax.lax.scan(body, state, jax.random.split(key, num_frames))
  return state, jnp.swapaxes(xs_NxBxD, 0, 1)


def frame_step(model, draw: Draw):
  """One frame of :func:`_smooth_scan` as a function of its random numbers: ``step(state, gumbel [B, K],
  normal [B, D]) -> (state, frame [B, D])`` (``heads.frame_numbers``: the scan draws them from each frame's
  key). What every frame of a smoothed dance runs, and what ``chorjax export`` writes as a graph."""
  pacing = draw.pacing if draw.pace else None
  lag = draw.pace_lag if pacing is not None else 1
  keep = 1.0 - 1.0 / (10 * lag)  # the running pace forgets over about ten lags (5 s)
  controls = draw.head_args()

  def step(c, gumbel_BxK, normal_BxD):
    carry, previous, filters, drawn, (recent, at, own) = c
    carry, out = model.step(carry, previous)
    filters, eps_BxD = smooth(filters, normal_BxD, draw.noise_smoothing, draw.noise_order, draw.noise_gain)
    governed = _governed(controls, own, pacing.ref, draw.pace) if pacing is not None else controls
    x, drawn = model.draw(out, gumbel_BxK, eps_BxD, drawn, **governed)
    x = x if draw.bounds is None else draw.bounds.clip(x, previous)
    if pacing is not None:
      own = keep * own + (1 - keep) * _moved(x, recent, at, pacing)
      recent, at = recent.at[at].set(x), (at + 1) % lag
    return (carry, x, filters, drawn, (recent, at, own)), x

  return step


def frame_program(graphdef, params, draw: Draw, batch: int):
  """:func:`frame_step` as a function of arrays for ``chorjax export`` (``Family.frame_program``):
  ``program(weights [B, M], start [B], gumbel [B, K], normal [B, D], *state) -> (frame [B, D], *state)``, where
  the dancers ``start`` marks begin from the weights' initial state (:func:`_smooth_start`), with example
  inputs (the state zeros) and the names of the inputs and outputs (``state.carry.0.1``, ``state.filters`` ...)."""
  model = nnx.merge(graphdef, params)
  b, d = batch, model.dim
  x0 = jnp.zeros((b, d), jnp.float32)
  fresh = lambda w, draw: _smooth_start(model.initial_carry(w), x0, draw, model.draw_start(x0[:, None]))
  weights_like = jax.ShapeDtypeStruct((b, model.num_motions), jnp.float32)
  template = jax.eval_shape(lambda w: fresh(w, draw.for_motion(w)), weights_like)
  top = ("carry", "previous", "filters", "drawn", "governor")
  treedef, args, inputs, outputs = frame_io(template, top, b, model.num_motions, model.num_mixtures, d)

  def program(weights, start, gumbel, normal, *leaves):
    held = draw.for_motion(weights)  # with labels, the pace of the weights' labels
    state = _restart(jax.tree.unflatten(treedef, leaves), fresh(weights, held), start > 0.5)
    state, x = frame_step(model, held)(state, gumbel, normal)
    return (x, *jax.tree.leaves(state))

  return program, args, inputs, outputs


def _restart(state, fresh, start_B):
  """``state`` with the dancers that ``start_B`` marks replaced by ``fresh`` (the governor's ring position,
  one for all dancers, is kept: a restarted dancer's ring holds one frame throughout)."""

  def pick(axis):
    return lambda f, s: jnp.where(jnp.reshape(start_B, [-1 if i == axis else 1 for i in range(f.ndim)]), f, s)

  carry, previous, filters, drawn, (recent, at, own) = state
  f_carry, f_previous, f_filters, f_drawn, (f_recent, _, f_own) = fresh
  first, second = pick(0), pick(1)
  return (
    jax.tree.map(first, f_carry, carry),
    first(f_previous, previous),
    second(f_filters, filters),
    jax.tree.map(first, f_drawn, drawn),
    (second(f_recent, recent), at, first(f_own, own)),
  )


def _governed(controls: dict, own_B, ref, gain) -> dict:
  """The draw's controls as the pace governor sets them for dancers at ``own`` pace (training pace ``ref``): the
  scale temperature times ``m = (ref / own) ** gain`` within 0.5-2x (a dancer who slows down gets more energy,
  one who races less), and the persistence times ``min(m, 1 / m) ** 2`` (off pace either way, the component
  it holds is what keeps it there: it lets go sooner; why both: ``docs/perf-notes.md``)."""
  m = jnp.clip((ref / jnp.maximum(own_B, 1e-6)) ** gain, 0.5, 2.0)[:, None]
  sigma, hold = controls["sigma_temperature"] * m, controls["persistence"] * jnp.minimum(m, 1 / m) ** 2
  return {**controls, "sigma_temperature": sigma, "persistence": hold}


def _moved(x_BxD, recent_LxBxD, at, pacing: Pacing):
  """How far each dancer moved over the governor's lag (``recent[at]`` is the frame ``lag`` frames before
  ``x``): with ``pacing.joints``, the judge's measure (``features.joint_pace``: joints relative to the root,
  the turn over the lag summed from the heading changes); else the mean absolute change of the features
  weighted by ``pacing.weights``."""
  then = recent_LxBxD[at]
  measure = pacing.joints
  if measure is None:
    return jnp.abs(x_BxD - then) @ pacing.weights
  lag = recent_LxBxD.shape[0]
  heading = recent_LxBxD[..., 0].sum(0) - then[:, 0] + x_BxD[:, 0]  # the changes of the lag frames up to x
  return joint_pace(x_BxD, then, heading * measure.std[0] + lag * measure.mean[0], measure)


def smooth_noise(filters_KxBxD, key, rho: float, order: int = 2):
  """Standard-normal noise correlated over frames: white noise through ``order`` cascaded AR(1) filters with
  coefficient ``rho``, scaled to unit stationary variance (:func:`noise_gain`). ``rho = 0``: white noise.
  Two filters (the default) give a smooth, low-pass process whose second difference still carries every
  frequency (its spectrum falls as the fourth power, which the second difference undoes); four or more
  leave far less frame-to-frame tremble at the same speed and forget sooner (at the same first difference,
  four at 0.8 have a third of two at 0.9's second difference, and half its correlation over a second).
  ``filters_KxBxD`` holds the filters' states (``K >= order``; the first ``order`` are used); returns
  ``(filters, noise [B, D])``."""
  return smooth(filters_KxBxD, jax.random.normal(key, filters_KxBxD.shape[1:], filters_KxBxD.dtype), rho, order)


def smooth(filters_KxBxD, white_BxD, rho, order: int = 2, gain=None):
  """:func:`smooth_noise` of the given white noise ``white_BxD``: ``(filters, noise [B, D])``; ``gain``:
  :func:`noise_gain` of ``rho`` and ``order`` where ``rho`` is traced (``Draw.noise_gain``)."""
  x = white_BxD
  states = []
  for k in range(order):
    x = rho * filters_KxBxD[k] + x
    states.append(x)
  return filters_KxBxD.at[:order].set(jnp.stack(states)), x * (noise_gain(rho, order) if gain is None else gain)


def dance(graphdef, params, features, motion, key, num_frames: int, controls: Controls, prime_BxPxD=None) -> np.ndarray:
  """Dancers in data space ``[B, T, J, 3]``: :func:`generate` with ``controls`` (clipped to the training range
  if asked), decoded (with rigid bones and locked feet if asked). A prime phrase comes first, decoded as one
  with its continuation (root-motion features integrate across the seam)."""
  draw = controls.draw(features)
  z = generate(graphdef, params, motion, key, num_frames=num_frames, draw=draw, prime_BxPxD=prime_BxPxD)
  if prime_BxPxD is not None:
    z = np.concatenate([prime_BxPxD, np.asarray(z)], axis=1)
  return np.asarray(features.decode(z, **controls.decoding()))


@functools.partial(jax.jit, static_argnames=("graphdef",))
def start_stream(graphdef, params, motion, draw: Draw, prime_BxPxD=None):
  """The state of an endless dance (:func:`continue_stream`) before its first frame: conditioned on
  ``motion`` and, with a prime, after its last frame (teacher forced over the phrase as :func:`generate`
  primes); ``draw``: the draw the stream will continue with (its governor's lag and training pace)."""
  model = nnx.merge(graphdef, params)
  carry, x0, before = _primed(model, motion, prime_BxPxD)
  return _smooth_start(carry, x0, draw, model.draw_start(*before))


@functools.partial(jax.jit, static_argnames=("graphdef", "num_frames"))
def continue_stream(graphdef, params, state, key, draw: Draw, *, num_frames: int):
  """The next ``num_frames`` of an endless dance: ``(state, normalized frames [B, N, D])``. The same draw
  as :func:`generate`'s smoothed path (``greedy``: the most likely component's mean), resumable chunk
  by chunk from :func:`start_stream`'s state; the temperatures may change between chunks."""
  model = nnx.merge(graphdef, params)
  if draw.greedy:
    draw = draw.replace(pi_temperature=0.0, sigma_temperature=0.0)
  return _smooth_scan(model, state, key, num_frames, draw)
