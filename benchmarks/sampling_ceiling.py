"""Where batch-64 sampling's time goes, against what the same matmuls alone can do (issue 21's 75% target).

    python -m benchmarks.sampling_ceiling            # about a minute on 2 cores
    python -m benchmarks.sampling_ceiling --unroll   # generate's unrolled loop against one frame per iteration

The model of ``benchmarks.run``'s sampling rows (LSTM 3 x 256, 8-component MDN, 48 features), 1,000 frames
at batch 64, each program one jitted ``lax.scan``, median of 5 runs after a compile:

- ``chorjax``: the recurrent family's ``generation.generate`` (the LSTM step and the MDN draw), as the benchmark
  times it;
- ``chorjax, no draw``: the same model's step, its output fed back without the MDN draw;
- ``plain LSTM``: the same matmuls and LSTM gates written as a user would (``jnp.split``, sigmoid, tanh);
- ``matmuls only``: the same matmuls with one tanh on a quarter of each layer's output (no gates): the
  ceiling any LSTM step with these shapes can reach here.

Prints each as seconds and as a fraction of the machine's matmul peak (``benchmarks.run.matmul_peak``,
measured after them).
"""

from __future__ import annotations

import sys

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks.run import matmul_peak, sampler_model
from benchmarks.timing import D, H, K, L, alternate, timed

B, FRAMES = 64, 1000
FLOPS_PER_FRAME = 2 * B * ((D + H) * 4 * H + (L - 1) * 2 * H * 4 * H + H * (K + 2 * K * D))


def _median_seconds(fn, *args, reps: int = 5) -> float:
  jax.block_until_ready(fn(*args, jax.random.key(0)))
  times = [timed(lambda i=i: fn(*args, jax.random.key(i + 1)), jax.block_until_ready) for i in range(reps)]
  return float(np.median(times))


def chorjax_programs():
  from flax import nnx

  from chorjax.families.recurrent.generation import UNROLL, _primed, generate

  graphdef, params = sampler_model()
  motion = jax.nn.one_hot(jnp.zeros(B, jnp.int32), 10)

  def no_draw(p, key):
    model = nnx.merge(graphdef, p)
    carry, x0, _ = _primed(model, motion, None)

    def body(c, _):
      carry, out = model.step(*c)
      return (carry, 0.1 * out[:, :D]), None

    return jax.lax.scan(body, (carry, x0), jax.random.split(key, FRAMES), unroll=UNROLL)[0][1]

  full = jax.jit(lambda p, key: generate(graphdef, p, motion, key, num_frames=FRAMES))
  return {"chorjax": (full, params), "chorjax, no draw": (jax.jit(no_draw), params)}


def plain_programs():
  from chorjax.families.recurrent.generation import UNROLL

  ks = jax.random.split(jax.random.key(0), 2 * L + 1)
  w_x = [0.05 * jax.random.normal(ks[i], (D if i == 0 else H, 4 * H)) for i in range(L)]
  w_h = [0.05 * jax.random.normal(ks[L + i], (H, 4 * H)) for i in range(L)]
  w_out = 0.05 * jax.random.normal(ks[-1], (H, K + 2 * K * D))
  weights = (w_x, w_h, w_out)

  def scan(layer, weights, key):
    w_x, w_h, w_out = weights

    def body(c, _):
      hs, cs, x = c
      new_h, new_c = [], []
      for l in range(L):
        h, cell = layer(x @ w_x[l] + hs[l] @ w_h[l], cs[l])
        new_h.append(h)
        new_c.append(cell)
        x = h
      return (new_h, new_c, (x @ w_out)[:, :D]), None

    zeros = [jnp.zeros((B, H))] * L
    return jax.lax.scan(body, (zeros, zeros, jnp.zeros((B, D))), None, length=FRAMES, unroll=UNROLL)[0][2]

  def lstm(z, c):
    i, f, g, o = jnp.split(z, 4, -1)
    c = jax.nn.sigmoid(f + 1.0) * c + jax.nn.sigmoid(i) * jnp.tanh(g)
    return jax.nn.sigmoid(o) * jnp.tanh(c), c

  def matmuls_only(z, c):
    return jnp.tanh(z[:, :H]), c

  return {
    "plain LSTM": (jax.jit(lambda w, key: scan(lstm, w, key)), weights),
    "matmuls only": (jax.jit(lambda w, key: scan(matmuls_only, w, key)), weights),
  }


def unroll_ab(reps: int = 5) -> dict:
  """The recurrent family's ``generation.generate`` with its loop unrolled by ``UNROLL`` against one frame per
  iteration, alternating: unroll -> median seconds per 1,000 frames at batch 64."""
  import chorjax.families.recurrent.generation

  graphdef, params = sampler_model()
  motion = jax.nn.one_hot(jnp.zeros(B, jnp.int32), 10)
  from chorjax.sampling.controls import Draw

  pairs = []
  for n in (1, chorjax.families.recurrent.generation.UNROLL):
    fn = jax.jit(
      lambda p, n=n: chorjax.families.recurrent.generation._generate.__wrapped__(
        graphdef, p, motion, jax.random.key(0), Draw(), num_frames=FRAMES, unroll=n
      )
    )
    compiled = fn.lower(params).compile()
    pairs.append((n, lambda compiled=compiled: compiled(params), jax.block_until_ready))
  return alternate(pairs, reps)


def main() -> None:
  if sys.argv[1:] == ["--unroll"]:
    for n, seconds in unroll_ab().items():
      print(f"unroll {n}: {seconds:.3f} s per {FRAMES} frames at batch {B}")
    return
  programs = {**chorjax_programs(), **plain_programs()}
  medians = {name: _median_seconds(fn, args) for name, (fn, args) in programs.items()}
  peak = matmul_peak()
  print(f"matmul peak {peak / 1e9:.0f} GFLOP/s; {FLOPS_PER_FRAME / 1e6:.0f} MFLOP of matmuls per frame at batch {B}")
  for name, seconds in medians.items():
    rate = FLOPS_PER_FRAME * FRAMES / seconds
    share = f"{rate / 1e9:6.1f} GFLOP/s  {100 * rate / peak:3.0f}% of peak"
    print(f"{name:18s} {seconds:.3f} s per {FRAMES} frames  {share}")


if __name__ == "__main__":
  main()
