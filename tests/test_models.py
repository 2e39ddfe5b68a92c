"""Models: shapes, jit equality, causality, MDN likelihood and sampling, step == scan, golden losses."""

import math

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import tiny_config
from scipy.special import logsumexp
from scipy.stats import norm

from chorjax.families.recurrent.recurrent_model import create_model
from chorjax.models import as_weights
from chorjax.models.heads import mdn_log_prob, mdn_params, mdn_sample
from chorjax.models.rnn import RecurrentCore, dropout_mask

CELLS, HEADS = ("lstm", "lnlstm", "gru"), ("mse", "mdn")
GRID = [(c, h) for c in CELLS for h in HEADS]


def make(cell, head, **kw):
  cfg = tiny_config(f"model.cell={cell}", f"model.head={head}", *[f"model.{k}={v}" for k, v in kw.items()])
  return create_model(cfg.model, dim=48, num_motions=10, seed=0)


def inputs(b=3, t=7, seed=0):
  x = jax.random.normal(jax.random.key(seed), (b, t, 48))
  return x, jnp.arange(b) % 10  # motion ids


@pytest.mark.parametrize("cell, head", GRID)
def test_shapes_finite_and_jit_equal(cell, head):
  m = make(cell, head)
  x, w = inputs()
  raw = m(x, w)
  p = 48 if head == "mse" else 3 + 3 * 48 + 3 * 48
  chex.assert_shape(raw, (3, 7, p))
  chex.assert_tree_all_finite(raw)
  from flax import nnx

  jitted = nnx.jit(lambda m, x, w: m(x, w))(m, x, w)
  np.testing.assert_allclose(jitted, raw, atol=1e-5)
  loss, aux = m.loss(raw, x)
  assert np.isfinite(float(loss))
  if head == "mse":
    np.testing.assert_allclose(aux["mse"], loss)
  else:  # the MSE of the mixture's mean, comparable with the MSE head's
    logpi, mu, _ = mdn_params(raw, 3, 48, False, 1e-3)
    mean = (np.exp(logpi)[..., None] * mu).sum(-2)
    np.testing.assert_allclose(aux["mse"], np.mean((mean - np.asarray(x)) ** 2), rtol=1e-5)


@pytest.mark.parametrize("cell, head", GRID)
def test_causality(cell, head):
  m = make(cell, head)
  x, w = inputs(b=1, t=6)
  t = 2
  jac = jax.jacrev(lambda x: m(x, w)[0, t].sum())(x)
  assert np.all(np.asarray(jac[0, t + 1 :]) == 0.0)
  assert np.abs(np.asarray(jac[0, : t + 1])).sum() > 0


@pytest.mark.parametrize("cell, head", GRID)
def test_step_reproduces_the_scan(cell, head):
  m = make(cell, head)
  x, w = inputs(t=9)
  raw = m(x, w)
  carry, outs = m.initial_carry(w), []
  for t in range(9):
    carry, r = m.step(carry, x[:, t])
    outs.append(r)
  np.testing.assert_allclose(jnp.stack(outs, 1), raw, atol=1e-6)


def test_motion_weights_choose_the_initial_state_and_blends_interpolate():
  m = make("lstm", "mse")
  x, _ = inputs(b=1)
  w4, w5 = as_weights(jnp.array([4]), 10), as_weights(jnp.array([5]), 10)
  assert not np.allclose(m(x, w4), m(x, w5))
  np.testing.assert_array_equal(m(x, w4), m(x, jnp.array([4])))  # ids are one-hot weights
  blend = 0.5 * w4 + 0.5 * w5
  c4, c5, cb = m.initial_carry(w4), m.initial_carry(w5), m.initial_carry(blend)
  np.testing.assert_allclose(cb[0][1], (c4[0][1] + c5[0][1]) / 2, atol=1e-6)  # dense layer is affine
  zero = make("lstm", "mse", initial_state="'zero'")
  np.testing.assert_allclose(zero(x, w4), zero(x, w5))


@pytest.mark.parametrize("cell", CELLS)
def test_motion_weights_beside_every_frame_condition_every_step(cell):
  """``model.condition_every_frame``: the weights ride in the carry and join every frame's input, so frame by
  frame is the window call, and with a zero initial state they still change every later frame."""
  m = make(cell, "mdn", condition_every_frame="true")
  x, w = inputs(t=9)
  raw, weights = m(x, w), as_weights(w, 10)
  carry, outs = m.initial_carry(w), []
  for t in range(9):
    carry, r = m.step(carry, x[:, t])
    outs.append(r)
  np.testing.assert_allclose(jnp.stack(outs, 1), raw, atol=1e-5)
  np.testing.assert_array_equal(carry[-1][0], weights)  # still the dancers' weights after nine frames
  zero = make(cell, "mdn", condition_every_frame="true", initial_state="'zero'")
  a, b = zero(x, jnp.array([4, 4, 4])), zero(x, jnp.array([5, 5, 5]))
  assert (np.abs(np.asarray(a - b))[:, -1].max(-1) > 1e-4).all()
  assert np.allclose(
    make(cell, "mdn", initial_state="'zero'")(x, jnp.array([4, 4, 4]))[:, -1],
    make(cell, "mdn", initial_state="'zero'")(x, jnp.array([5, 5, 5]))[:, -1],
  )


def test_dropout_uses_one_mask_for_all_time_steps():
  mask = dropout_mask(jax.random.key(0), (4, 1, 32), 0.5)
  assert set(np.unique(np.asarray(mask))) == {0.0, 2.0}
  core = RecurrentCore("lstm", 8, 32, 2, 3, dropout=0.5, rngs=__import__("flax").nnx.Rngs(0))
  x = jnp.ones((4, 5, 8))
  carry = core.initial_carry(jnp.ones((4, 3)) / 3)
  out, _ = core(x, carry, jax.random.key(1))
  zeros = np.asarray(out) == 0.0
  assert zeros.any() and (zeros == zeros[:, :1]).all()  # the same units are dropped at every step
  np.testing.assert_array_equal(core(x, carry, jax.random.key(1))[0], out)


# ---------------------------------------------------------------- MDN maths


def raw_mdn(key, lead, k, d, s):
  return jax.random.normal(key, lead + (k + k * d + k * s,)) * 2.0


@pytest.mark.parametrize("isotropic", [False, True])
def test_mdn_nll_equals_an_independent_scipy_computation(isotropic):
  k, d = 4, 48
  s = 1 if isotropic else d
  raw = raw_mdn(jax.random.key(0), (5,), k, d, s)
  x = jax.random.normal(jax.random.key(1), (5, d))
  logpi, mu, scale = mdn_params(raw, k, d, isotropic, 1e-3)
  got = np.asarray(mdn_log_prob(logpi, mu, scale, x))
  r = np.asarray(raw, np.float64)
  logits, mu_np, sc = r[:, :k], r[:, k : k + k * d].reshape(5, k, d), r[:, k + k * d :].reshape(5, k, s)
  sc = np.maximum(np.log1p(np.exp(sc)), 1e-3)
  logw = logits - logsumexp(logits, axis=-1, keepdims=True)
  comp = norm.logpdf(np.asarray(x, np.float64)[:, None, :], mu_np, np.broadcast_to(sc, mu_np.shape)).sum(-1)
  want = logsumexp(logw + comp, axis=-1)
  np.testing.assert_allclose(got, want, rtol=1e-5)


def test_mdn_nll_is_finite_for_tiny_scales_in_48_dims():
  k, d = 8, 48
  raw = jnp.full((2, k + 2 * k * d), -50.0)  # softplus(-50) ~ 2e-22 -> floored
  x = jnp.ones((2, d)) * 3.0
  logpi, mu, scale = mdn_params(raw, k, d, False, 1e-3)
  lp = mdn_log_prob(logpi, mu, scale, x)
  assert np.all(np.isfinite(np.asarray(lp))) and float(scale.min()) == pytest.approx(1e-3)
  g = jax.grad(lambda r: -mdn_log_prob(*mdn_params(r, k, d, False, 1e-3), x).sum())(raw)
  assert np.all(np.isfinite(np.asarray(g)))


def test_mdn_with_one_component_and_fixed_scale_is_scaled_mse_plus_constant():
  d, s = 48, 0.7
  x = jax.random.normal(jax.random.key(2), (6, d))
  mu = jax.random.normal(jax.random.key(3), (6, d))
  raw_scale = math.log(math.expm1(s))  # softplus^-1
  raw = jnp.concatenate([jnp.zeros((6, 1)), mu, jnp.full((6, d), raw_scale)], axis=-1)
  nll = -mdn_log_prob(*mdn_params(raw, 1, d, False, 1e-3), x)
  mse = jnp.mean(jnp.square(x - mu), axis=-1)
  const = d * math.log(s) + 0.5 * d * math.log(2 * math.pi)
  np.testing.assert_allclose(nll, d / (2 * s**2) * mse + const, rtol=1e-5)


def test_mdn_gradients_match_finite_differences():
  k, d = 2, 3
  raw = raw_mdn(jax.random.key(4), (), k, d, d) * 0.5
  x = jax.random.normal(jax.random.key(5), (d,))
  f = lambda r: -mdn_log_prob(*mdn_params(r, k, d, False, 1e-3), x)
  g = np.asarray(jax.grad(f)(raw))
  eps = 1e-2
  for i in range(raw.shape[0]):
    e = jnp.zeros_like(raw).at[i].set(eps)
    fd = (float(f(raw + e)) - float(f(raw - e))) / (2 * eps)
    assert fd == pytest.approx(g[i], rel=2e-2, abs=2e-3), i


def test_mdn_sampling_reproduces_a_known_mixture():
  n = 40_000
  logpi = jnp.log(jnp.array([[0.2, 0.8]]))
  mu = jnp.array([[[-3.0, 1.0], [4.0, 0.0]]])  # 7 sigma apart on x: no overlap
  scale = jnp.array([[[0.5, 0.5], [1.0, 2.0]]])
  rep = lambda a: jnp.repeat(a, n, axis=0)
  x = np.asarray(mdn_sample(jax.random.key(0), rep(logpi), rep(mu), rep(scale)))
  first = x[:, 0] < 0.5
  assert first.mean() == pytest.approx(0.2, abs=0.01)
  np.testing.assert_allclose(x[first].mean(0), [-3.0, 1.0], atol=0.05)
  np.testing.assert_allclose(x[first].std(0), [0.5, 0.5], rtol=0.05)
  np.testing.assert_allclose(x[~first].std(0), [1.0, 2.0], rtol=0.05)
  # pi temperature sharpens; sigma temperature shrinks
  sharp = np.asarray(mdn_sample(jax.random.key(1), rep(logpi), rep(mu), rep(scale), pi_temperature=0.5))
  assert (sharp[:, 0] < 0.5).mean() == pytest.approx(1 / 17, abs=0.01)  # 0.2^2 / (0.2^2 + 0.8^2)
  cold = np.asarray(mdn_sample(jax.random.key(2), rep(logpi), rep(mu), rep(scale), sigma_temperature=0.1))
  np.testing.assert_allclose(cold[cold[:, 0] > 0.5].std(0), [0.1, 0.2], rtol=0.05)


def test_zero_temperature_and_greedy_are_deterministic():
  raw = raw_mdn(jax.random.key(6), (4,), 3, 5, 5)
  p = mdn_params(raw, 3, 5, False, 1e-3)
  g1 = mdn_sample(jax.random.key(0), *p, greedy=True)
  g2 = mdn_sample(jax.random.key(9), *p, greedy=True)
  np.testing.assert_array_equal(g1, g2)
  best = np.asarray(jnp.argmax(p[0], -1))
  np.testing.assert_allclose(g1, np.asarray(p[1])[np.arange(4), best])
  t1 = mdn_sample(jax.random.key(0), *p, pi_temperature=0.0, sigma_temperature=0.0)
  t2 = mdn_sample(jax.random.key(5), *p, pi_temperature=0.0, sigma_temperature=0.0)
  np.testing.assert_array_equal(t1, t2)
  np.testing.assert_array_equal(t1, g1)


# ---------------------------------------------------------------- golden one-step losses

# Update a number only when a change to the model or data pipeline is intended.
GOLDEN = {"mse": 0.87391311, "mdn": 65.211639}


@pytest.mark.parametrize("head", HEADS)
def test_golden_one_step_loss(head):
  from chorjax.data.dataset import WindowSampler, load_dataset

  cfg = tiny_config(f"model.head={head}", "model.cell=lnlstm")
  ds = load_dataset(cfg.data)
  batch = WindowSampler(ds.train, cfg.data.seq_length, cfg.train.batch_size, seed=0).batch(0)
  m = create_model(cfg.model, 48, ds.num_motions, seed=0)
  loss, _ = m.loss(m(jnp.asarray(batch["inputs"]), batch["motion_ids"]), batch["targets"])
  assert float(loss) == pytest.approx(GOLDEN[head], rel=1e-5)


@pytest.fixture(scope="module")
def real_batch():
  """Windows of the bundled CMU subject 94 dance, normalized as training sees them."""
  from chorjax.data.dataset import WindowSampler, load_dataset

  cfg = tiny_config("data.seq_length=40")
  ds = load_dataset(cfg.data)
  return WindowSampler(ds.train, 40, 6, seed=0).batch(0), ds.num_motions


def _close(a, b, tol=1e-5):
  """Equal to ``tol`` relative to the largest magnitude (leaf by leaf)."""
  for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
    np.testing.assert_allclose(x, y, rtol=0, atol=tol * max(1.0, float(jnp.max(jnp.abs(y)))))


@pytest.mark.parametrize("cell_name", CELLS)
def test_fused_layer_equals_the_plain_scan_in_outputs_and_gradients(real_batch, cell_name):
  from flax import nnx

  from chorjax.models.cells import CELLS as CELL_CLASSES
  from chorjax.models.fused import gru_scan, lnlstm_scan, lstm_scan

  batch, _ = real_batch
  cls = CELL_CLASSES[cell_name]
  cell = cls(48, 32, rngs=nnx.Rngs(params=1))
  xp = cell.project(jnp.swapaxes(jnp.asarray(batch["inputs"]), 0, 1))  # [T, B, G] of real frames
  k = jax.random.split(jax.random.key(2), 8)
  carry = tuple(0.5 * jax.random.normal(k[j], (6, 32)) for j in range(cls.num_carries))
  probe_h, probe_c = jax.random.normal(k[2], (40, 6, 32)), jax.random.normal(k[3], (6, 32))
  # the small parameters away from their initial values, so that their gradients matter
  params = {
    "w_h": cell.w_h[...],
    **{name: v + 0.3 * jax.random.normal(k[4], v.shape) for name, v in cell.loop_params().items()},
  }
  fused = {
    "lstm": lambda p, xp, carry: lstm_scan(p["w_h"], xp, *carry),
    "lnlstm": lambda p, xp, carry: lnlstm_scan(p["w_h"], p["gain_h"], p["gain_c"], p["bias_c"], xp, *carry),
    "gru": lambda p, xp, carry: gru_scan(p["w_h"], p["b_h"], xp, *carry),
  }[cell_name]

  def plain(p, xp, carry):  # lax.scan of the cell's step, differentiated by JAX
    loop_params = {k: v for k, v in p.items() if k != "w_h"}
    return jax.lax.scan(lambda c, xp_t: cls.recurrent_update(loop_params, xp_t, c[-1] @ p["w_h"], c), carry, xp)

  def objective(scan, p, xp, carry):
    last, hs = scan(p, xp, carry)
    return jnp.sum(hs * probe_h) + jnp.sum(last[0] * probe_c) + jnp.sum(last[-1]), hs

  grads = lambda scan: jax.value_and_grad(objective, argnums=(1, 2, 3), has_aux=True)(scan, params, xp, carry)
  got, want = grads(fused), grads(plain)
  _close(got[0], want[0])  # loss and every output frame
  _close(got[1], want[1])  # gradients for w_h and the small parameters, the projections and the carry
  assert all(float(jnp.abs(g).max()) > 0 for g in jax.tree.leaves(got[1]))


@pytest.mark.parametrize("cell_name", CELLS)
def test_model_gradients_through_the_fused_layer_equal_the_plain_scan(real_batch, monkeypatch, cell_name):
  from flax import nnx

  from chorjax.families.recurrent.steps import StepSpec, _loss_fn
  from chorjax.models.cells import CELLS

  batch, num_motions = real_batch
  cfg = tiny_config(
    f"model.cell={cell_name}", "model.head=mdn", "model.num_layers=3", "model.hidden_size=32", "model.dropout=0.2"
  )
  graphdef, params = nnx.split(create_model(cfg.model, 48, num_motions, 0), nnx.Param)
  spec = StepSpec(graphdef, None, None, input_noise=0.01, dropout=0.2)
  grad = lambda: jax.jit(jax.value_and_grad(lambda p: _loss_fn(p, batch, jax.random.key(3), spec), has_aux=True))
  fused = grad()(params)
  # lax.scan of the step, differentiated by JAX
  monkeypatch.setattr(CELLS[cell_name], "scan", lambda self, carry, xp: jax.lax.scan(self.step, carry, xp))
  plain = grad()(params)
  _close(fused[0][0], plain[0][0])
  _close(nnx.to_pure_dict(fused[1]), nnx.to_pure_dict(plain[1]))


def test_dense_equals_the_plain_matmul_in_outputs_and_gradients(real_batch):
  from chorjax.models.fused import dense

  batch, _ = real_batch
  x = jnp.asarray(batch["inputs"])  # [B, T, 48] real frames
  k = jax.random.split(jax.random.key(5), 3)
  w = jax.random.normal(k[0], (4, x.shape[-1], 24)) / 7  # a stack of 4: vmapped as a vectorized sweep does
  probe = jax.random.normal(k[1], x.shape[:-1] + (24,))

  def grads(matmul):
    f = lambda x, w: jnp.sum(jnp.tanh(matmul(x, w)) * probe)
    first = jax.vmap(jax.value_and_grad(f, argnums=(0, 1)), in_axes=(None, 0))(x, w)
    # a gradient of a gradient, as the GAN critic's gradient penalty takes
    penalty = lambda w: jnp.sum(jnp.square(jax.grad(f)(x, w)))
    return first, jax.grad(penalty)(w[0])

  got, want = grads(dense), grads(lambda x, w: x @ w)
  _close(got, want)
  assert float(jnp.abs(got[1]).max()) > 0


def _cudnn_by_reference(x, h0, c0, weights, lengths, *, input_size, hidden_size, num_layers, dropout, bidirectional):
  """``jax.experimental.rnn.lstm``'s cuDNN call, computed by the reference LSTM JAX's own tests hold cuDNN to."""
  from jax.experimental import rnn

  unpacked = rnn.unpack_lstm_weights(weights, input_size, hidden_size, num_layers, bidirectional)
  return rnn.lstm_ref(x, h0, c0, *unpacked, lengths, input_size, hidden_size, num_layers, dropout, bidirectional)


def test_the_cudnn_kernel_computes_what_the_fused_lstm_does(real_batch, monkeypatch):
  """``model.lstm_kernel = "cudnn"`` hands cuDNN the LSTM's weights in its layout; with the call computed by
  JAX's reference LSTM (cuDNN itself needs an NVIDIA GPU), the model's outputs and gradients on real
  windows equal the fused kernel's, dropout included. On this CPU the option leaves the fused kernel on."""
  from flax import nnx
  from jax.experimental import rnn

  from chorjax.errors import UserError
  from chorjax.models import rnn as core

  batch, num_motions = real_batch
  x, y, ids = (jnp.asarray(batch[k]) for k in ("inputs", "targets", "motion_ids"))
  fused, cudnn = (
    create_model(
      tiny_config("model.cell=lstm", "model.dropout=0.3", f"model.lstm_kernel={k}").model, 48, num_motions, 3
    )
    for k in ("fused", "cudnn")
  )
  assert not core.on_cuda()
  calls = []
  monkeypatch.setattr(rnn, "lstm", lambda *a, **kw: calls.append(1) or _cudnn_by_reference(*a, **kw))
  key = jax.random.key(1)

  def loss_and_grads(model):
    graphdef, params = nnx.split(model, nnx.Param)
    return jax.value_and_grad(lambda p: nnx.merge(graphdef, p).loss(nnx.merge(graphdef, p)(x, ids, key), y)[0])(params)

  on_cpu = loss_and_grads(cudnn)
  assert calls == []  # not on CUDA: the fused kernel
  monkeypatch.setattr(core, "on_cuda", lambda: True)
  want, got = loss_and_grads(fused), loss_and_grads(cudnn)
  assert len(calls) == cudnn.core.num_layers
  _close(got, want)
  _close(on_cpu, want, tol=0)
  assert float(jnp.abs(got[1]["core"]["cells"][0]["w_h"][...]).max()) > 0
  # the weights in cuDNN's layout are the cell's, gate by gate: a swapped gate pair would not match
  cell = cudnn.core.cells[0]
  w_ih, w_hh, b_ih, _ = rnn.unpack_lstm_weights(cell.cudnn_weights(), 48, cell.hidden, 1, False)
  np.testing.assert_array_equal(w_ih[0], cell.w_x[...].T)
  np.testing.assert_array_equal(w_hh[0], cell.w_h[...].T)
  np.testing.assert_array_equal(b_ih[0], cell.b[...])
  with pytest.raises(UserError, match=r"key 'model\.lstm_kernel': 'cudnn' runs the rnn family's plain LSTM only"):
    tiny_config("model.cell=lnlstm", "model.lstm_kernel=cudnn")


@pytest.mark.parametrize("seeds", [None, 2])
@pytest.mark.parametrize("cell_name", ["lstm", "lnlstm"])
def test_the_fused_loops_work_in_place_without_copying_their_buffer(cell_name, seeds):
  """The (LN-)LSTM's loops overwrite one [T, B, 4H] buffer row by row (projections -> gate activations ->
  gate gradients); the compiled forward and backward must hold no copy of an array that size, which XLA
  makes every step when a loop reads a row of the buffer before writing another. Also vmapped over seeds,
  as vectorized training runs them."""
  from chorjax.models.fused import lnlstm_scan, lstm_scan

  frames, batch, hidden = 40, 6, 32
  k = jax.random.split(jax.random.key(0), 4)
  w_h = 0.1 * jax.random.normal(k[0], (hidden, 4 * hidden))
  xp = jax.random.normal(k[1], (frames, batch, 4 * hidden))
  zeros = jnp.zeros((batch, hidden))
  gains = (jnp.ones((4, hidden)), jnp.ones(hidden), jnp.zeros(hidden))
  layer = {
    "lstm": lambda w, x: lstm_scan(w, x, zeros, zeros),
    "lnlstm": lambda w, x: lnlstm_scan(w, *gains, x, zeros, zeros),
  }[cell_name]
  loss = lambda w, x: jnp.sum(layer(w, 2.0 * x)[1] ** 2)  # the projections made inside the program, as in a model
  grad = jax.grad(loss, argnums=(0, 1))
  if seeds:
    grad, w_h, xp = jax.vmap(grad), jnp.stack([w_h] * seeds), jnp.stack([xp] * seeds)
  hlo = jax.jit(grad).lower(w_h, xp).compile().as_text()
  assert " while(" in hlo
  big = f"f32[{f'{seeds},' if seeds else ''}{frames},{batch},{4 * hidden}]"
  copies = [line for line in hlo.splitlines() if f"= {big}" in line and " copy(" in line]
  assert not copies, copies[:3]
