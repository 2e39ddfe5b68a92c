"""``model.mdn_basis = "pca"``: the MDN's diagonal Gaussians in the training frames' principal axes."""

import dataclasses

import jax
import numpy as np
import pytest
from flax import nnx
from helpers import QUICKSTART_SAMPLING, TINY, tiny_config
from scipy.stats import multivariate_normal

from chorjax.config import load_config
from chorjax.data.dataset import load_dataset
from chorjax.data.features import principal_axes
from chorjax.errors import UserError
from chorjax.models.heads import MDNHead
from chorjax.run import load_run
from chorjax.sample import sample_dancers
from chorjax.training.driver import train_and_evaluate


def test_principal_axes_find_the_direction_the_data_varies_along():
  rng = np.random.default_rng(0)
  t = rng.normal(size=5000)
  x = np.stack([t + 0.05 * rng.normal(size=5000), t + 0.05 * rng.normal(size=5000), 0.3 * rng.normal(size=5000)], 1)
  b = principal_axes(x)
  np.testing.assert_allclose(b.T @ b, np.eye(3), atol=1e-6)  # a rotation
  np.testing.assert_allclose(b[:, 0], [0.5**0.5, 0.5**0.5, 0.0], atol=0.01)  # x0 and x1 move together
  np.testing.assert_allclose(np.abs(b[:, 1]), [0.0, 0.0, 1.0], atol=0.01)  # then x2
  v = (x @ b).var(0)
  assert v[0] > v[1] > v[2]
  with pytest.raises(ValueError, match="frames"):
    principal_axes(x[:1])


def test_a_librarys_axes_are_summed_take_by_take_to_the_same_covariance(monkeypatch):
  """Frames too many for one float64 copy: the covariance is summed take by take, and it is numpy's to float64
  rounding, on the bundled takes' features (so the axes with distinct variances are the same ones)."""
  import chorjax.data.features as features

  takes = [z for _, z in load_dataset(load_config("configs/quickstart.toml").data).train]
  n = sum(len(t) for t in takes)
  whole = features._covariance(takes, n)
  np.testing.assert_allclose(whole, np.cov(np.concatenate(takes).astype(np.float64), rowvar=False), rtol=0, atol=0)
  monkeypatch.setattr(features, "COVARIANCE_IN_ONE", 0)
  streamed = features._covariance(takes, n)
  assert np.abs(streamed - whole).max() < 1e-9 * np.abs(whole).max()
  once, summed = principal_axes(np.concatenate(takes)), principal_axes(takes)
  np.testing.assert_allclose(summed.T @ summed, np.eye(len(whole)), atol=1e-5)
  variance = np.sort(np.linalg.eigvalsh(whole))[::-1]
  distinct = np.flatnonzero(
    np.minimum(-np.diff(variance, prepend=np.inf), -np.diff(variance, append=-np.inf)) > 1e-3 * variance[0]
  )
  assert len(distinct) >= 10
  np.testing.assert_allclose(summed[:, distinct], once[:, distinct], atol=1e-4)


def _head_with_basis(d, k, seed):
  head = MDNHead(8, d, num_mixtures=k, basis=True, rngs=nnx.Rngs(seed))
  q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(d, d)))
  head.basis[...] = q.astype(np.float32)
  return head, q


def test_the_rotated_mixture_is_a_full_covariance_gaussian_in_feature_space():
  """One component, diagonal scales s in the basis B: the NLL of a feature frame x is that of
  N(B mu, B diag(s^2) B^T), and draws have that covariance."""
  d = 5
  head, q = _head_with_basis(d, 1, 0)
  out = np.random.default_rng(1).normal(size=(3, head.num_outputs)).astype(np.float32)
  x = np.random.default_rng(2).normal(size=(3, d)).astype(np.float32)
  _, mu, scale = (np.asarray(a, np.float64) for a in head.params(out))
  for i in range(3):
    full = multivariate_normal(q @ mu[i, 0], q @ np.diag(scale[i, 0] ** 2) @ q.T)
    nll = float(head.loss(out[i : i + 1], x[i : i + 1])[0])
    assert nll == pytest.approx(-full.logpdf(x[i]), rel=1e-4)
  np.testing.assert_allclose(head.mean(out), mu[:, 0] @ q.T, atol=1e-5)
  many = np.repeat(out[:1], 40_000, 0)
  draws = np.asarray(head.sample(many, jax.random.key(0)), np.float64)
  want = q @ np.diag(scale[0, 0] ** 2) @ q.T
  np.testing.assert_allclose(np.cov(draws, rowvar=False), want, atol=0.05 * np.abs(want).max())


def test_a_pca_run_fixes_its_basis_from_its_training_frames_and_never_trains_it(tmp_path):
  w = tmp_path / "run"
  cfg = tiny_config(
    "train.num_steps=6",
    "log.tensorboard=false",
    "model.mdn_basis=pca",
    "optim.name=adamw",
    "optim.weight_decay=0.5",  # would shrink a trained basis
    *QUICKSTART_SAMPLING,
  )
  train_and_evaluate(cfg, w)
  ds = load_dataset(cfg.data)
  want = principal_axes([z for _, z in ds.train])
  run = load_run(w)
  np.testing.assert_allclose(np.asarray(run.params["head"]["basis"]), want, atol=1e-6)
  pos, _ = sample_dancers(run, 40, 2, 0)
  assert pos.shape[:2] == (2, 40) and np.isfinite(pos).all()
  # sample.ground stands on the floor the run recorded; a run recorded without one measures it on its takes
  assert run.features.floor == pytest.approx(ds.features.floor) and ds.features.floor is not None
  older = dataclasses.replace(run, features=dataclasses.replace(run.features, floor=None))
  for r in (run, older):
    grounded, settings = sample_dancers(r, 40, 2, 0, controls={"ground": True})
    assert settings["ground"] and np.isfinite(grounded).all()
    np.testing.assert_allclose(grounded[..., [0, 2]], pos[..., [0, 2]], atol=1e-4)  # only heights move


def test_an_acceleration_basis_is_the_principal_axes_of_the_frames_second_differences(tmp_path):
  """``model.mdn_basis = "acceleration"``: the axes of how the training frames change from one frame to the
  next but one (what an MDN carrying its residuals draws), not of the frames; fixed like the pose axes. The
  foot contacts (0/1 flags, the canonical features' last two) are axes of their own that carry nothing: drawn
  about the means, they neither stay planted nor wander off."""
  import jax.numpy as jnp
  from flax import nnx

  flags = ["train.num_steps=3", "log.tensorboard=false", "data.representation=canonical"]
  cfg = tiny_config(*flags, "model.mdn_basis=acceleration", "model.mdn_memory=2")
  train_and_evaluate(cfg, tmp_path / "run")
  train = [z for _, z in load_dataset(cfg.data).train]
  run = load_run(tmp_path / "run")
  basis = np.asarray(run.params["head"]["basis"])
  np.testing.assert_allclose(basis[:-2, :-2], principal_axes([np.diff(z[:, :-2], 2, axis=0) for z in train]), atol=1e-6)
  np.testing.assert_array_equal(basis[-2:], np.eye(len(basis))[-2:])
  np.testing.assert_array_equal(basis[:, -2:], np.eye(len(basis))[:, -2:])
  assert np.abs(basis - principal_axes(train)).max() > 0.1  # another basis than the frames'
  head = nnx.merge(run.graphdef, run.params).head
  out = jnp.asarray(np.random.default_rng(0).normal(size=(3, head.num_outputs)), jnp.float32)
  residuals = [jnp.ones((3, head.num_mixtures, head.dim))] * 2
  _, carried, _ = head.carried(out, residuals)
  mu = head.params(out)[1]
  assert head.white == 2 and np.array_equal(carried[..., -2:], mu[..., -2:])
  assert np.abs(carried[..., :-2] - mu[..., :-2]).min() > 0  # the other axes carry


def test_an_mse_head_ignores_the_quickstarts_basis_and_trains(tmp_path):
  """The quickstart with `model.head=mse` (an MDN-vs-MSE comparison): the basis and the carried residuals are the
  MDN's, so an MSE head has neither (as it has no mixtures), and trains."""
  cfg = load_config("configs/quickstart.toml", ["model.head=mse", *TINY, "train.calibrate=false"])
  assert cfg.model.mdn_basis == "acceleration" and not cfg.model.pca_basis and not cfg.model.memory
  train_and_evaluate(cfg, tmp_path / "w")
  assert "basis" not in load_run(tmp_path / "w").params["head"]


@pytest.mark.parametrize("key", ["foot_lock", "ground"])
def test_feet_controls_on_other_features_are_refused_before_training(key):
  """`sample.foot_lock` and `sample.ground` need canonical features: the quickstart with another representation
  is one line naming the key when the config loads, not a failure after training."""
  with pytest.raises(UserError, match=rf"key 'sample\.{key}'.*canonical.*'directions'"):
    other = "ground" if key == "foot_lock" else "foot_lock"
    load_config("configs/quickstart.toml", ["data.representation=directions", f"sample.{other}=false"])
