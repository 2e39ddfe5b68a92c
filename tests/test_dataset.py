"""Dataset: ids from file names, split by take, train-only statistics, deterministic batches."""

import numpy as np
import pytest
from helpers import ROOT, tiny_config

from chorjax.config import load_config
from chorjax.data import transforms
from chorjax.data.dataset import WindowSampler, bundled_path, eval_windows, load_dataset, read_takes
from chorjax.errors import UserError


@pytest.fixture(scope="module")
def ds():
  return load_dataset(load_config(None, ["data.seq_length=20"]).data)


def test_ids_split_and_train_only_statistics(ds):
  assert list(ds.id_map) == sorted(ds.id_map) and list(ds.id_map.values()) == list(range(10))
  assert ds.val_names == ("94_10_skeleton_3d",) and len(ds.train_names) == 9
  train = np.concatenate([x for _, x in ds.train])
  np.testing.assert_allclose(train.mean(0), 0, atol=1e-4)
  np.testing.assert_allclose(train.std(0, ddof=1), 1, atol=1e-4)
  val = np.concatenate([x for _, x in ds.val])
  assert np.abs(val.mean(0)).max() > 1e-3  # the held-out take was not used for the statistics


def test_val_takes_by_name_and_id_and_errors():
  cfg = load_config(None, ["data.val_takes=[0, '94_05_skeleton_3d']"])
  assert load_dataset(cfg.data).val_names == ("94_01_skeleton_3d", "94_05_skeleton_3d")
  with pytest.raises(UserError, match="no take named 'nope'"):
    load_dataset(load_config(None, ["data.val_takes=['nope']"]).data)
  # a library holds out by pattern (a trial of every label); the errors name the key
  by_pattern = load_dataset(load_config(None, ["data.val_pattern='_0[59]_'"]).data)
  assert by_pattern.val_names == ("94_05_skeleton_3d", "94_09_skeleton_3d") and len(by_pattern.train_names) == 8
  for bad, says in [
    (["data.val_pattern='_77_'"], "finds no take"),
    (["data.val_pattern='('"], "not a regular expression"),
    (["data.val_pattern='_'"], "data.val_pattern: holds out every take"),
    (["data.val_pattern='_05'", "data.val_takes=[0]"], "not both"),
  ]:
    with pytest.raises(UserError, match=says):
      load_dataset(load_config(None, bad).data)


def test_augmentations_add_sequences():
  cfg = load_config(None, ["data.augment=['reverse', 'mirror']"])
  ds = load_dataset(cfg.data)
  assert len(ds.train) == 4 * 9
  (i0, a), (i1, b), (i2, c), (i3, d) = ds.train[:4]
  assert i0 == i1 == i2 == i3 == 0
  np.testing.assert_allclose(c, a[::-1], atol=1e-5)  # reversed copy of the original
  np.testing.assert_allclose(d, b[::-1], atol=1e-5)  # reversed copy of the mirrored one
  # the mirrored copy: twin joints swapped and the lateral axis negated, in y-up positions
  canon = lambda z: np.asarray(ds.features.canonical(ds.features.decode(z)))
  twins = ds.features.skeleton.twins
  np.testing.assert_allclose(canon(b), np.asarray(transforms.mirror(canon(a), twins, lateral_axis=0)), atol=1e-4)
  assert not np.allclose(canon(b), canon(a), atol=1e-2)


def test_batches_are_deterministic_real_windows(ds):
  s = WindowSampler(ds.train, seq_length=20, batch_size=16, seed=3)
  b1, b2, b3 = s.batch(7), WindowSampler(ds.train, 20, 16, 3).batch(7), s.batch(8)
  for k in b1:
    np.testing.assert_array_equal(b1[k], b2[k])
  assert not np.array_equal(b1["inputs"], b3["inputs"])
  assert b1["inputs"].shape == (16, 20, 48) and b1["motion_ids"].shape == (16,)
  np.testing.assert_array_equal(b1["inputs"][:, 1:], b1["targets"][:, :-1])
  seq, start = s.indices(7)
  for r in range(16):
    mid, x = ds.train[seq[r]]
    assert b1["motion_ids"][r] == mid
    np.testing.assert_array_equal(b1["inputs"][r], x[start[r] : start[r] + 20])
  # process shares: rows of the global batch
  np.testing.assert_array_equal(s.batch(7, slice(4, 8))["inputs"], b1["inputs"][4:8])


def test_takes_are_drawn_in_proportion_to_length(ds):
  s = WindowSampler(ds.train, seq_length=20, batch_size=1000, seed=0)
  counts = np.bincount(np.concatenate([s.indices(k)[0] for k in range(20)]), minlength=9)
  expected = s.probs * counts.sum()
  chi2 = ((counts - expected) ** 2 / expected).sum()
  assert chi2 < 30  # 8 degrees of freedom: p < 0.001 above ~26


def test_eval_windows_cover_the_held_out_take(ds):
  w = eval_windows(ds.val, 20, max_windows=1000)
  assert w["inputs"].shape == ((740 - 1) // 20, 20, 48)
  assert (w["motion_ids"] == 9).all()
  assert eval_windows(ds.val, 20, max_windows=5)["inputs"].shape[0] == 5


def test_the_dancers_benchmark_holds_out_whole_takes_partners_together_and_nothing_leaks(shared_data):
  """The splits of experiments/dancers/sweep.toml: cmu94 and martial hold out the pairs split.py chose
  (whole takes, none trained on); both salsa partners of a take are held out together, and no held-out
  frame, nor its left/right mirror, is among the training frames (the mirror augmentation is applied to the
  training takes only)."""
  from pathlib import Path

  from chorjax.sweeps import load_sweep, sweep_points

  root = Path(__file__).resolve().parents[1]
  sweep = load_sweep(root / "experiments" / "dancers" / "sweep.toml")
  points = dict(sweep_points(sweep))
  base = root / "experiments" / "dancers" / sweep["base"]
  read = lambda point, *more: load_dataset(load_config(base, [*points[point], *more]).data)
  cmu94 = read("split-cmu94-seed=0")
  assert set(cmu94.val_names) == {"94_05_skeleton_3d", "94_08_skeleton_3d"} and len(cmu94.train_names) == 8
  martial = read("split-martial-seed=0", f"data.dataset='{shared_data / 'aclstm' / 'martial'}'")
  assert set(martial.val_names) == {"03", "07"} and set(martial.train_names) == {"04", "06", "08", "10"}
  ds = read("split-salsa-seed=0", f"data.dataset='{shared_data / 'aclstm' / 'salsa'}'")
  held = set(ds.val_names)
  assert held == {"12", "27", "14", "29"} and not held & set(ds.train_names)
  assert all(f"{int(n) + 15 if int(n) <= 15 else int(n) - 15:02d}" in held for n in held)  # NN and NN+15 dance together
  assert len(ds.train) == 2 * len(ds.train_names)  # the quickstart mirrors every training take

  f = ds.features
  canon = lambda z: np.asarray(f.canonical(f.decode(z)))
  mirrored = lambda z: np.asarray(f.encode(f.uncanonical(transforms.mirror(canon(z), f.skeleton.twins))))
  train = np.concatenate([x for _, x in ds.train]).astype(np.float64)

  def nearest(q):  # each frame's distance to its nearest training frame
    q = np.asarray(q, np.float64)
    d2 = (q**2).sum(1)[:, None] + (train**2).sum(1)[None] - 2 * q @ train.T
    return np.sqrt(np.maximum(d2.min(1), 0.0))

  val = [x for _, x in ds.val]
  assert nearest(np.concatenate(val)).min() > 0.1  # 0.8 here; a copied frame would be ~1e-4 away
  assert nearest(np.concatenate([mirrored(x) for x in val])).min() > 0.1
  _, first = ds.train[0]  # ... as a training take's own mirror, kept in training, is
  assert nearest(mirrored(first)).max() < 0.01


def test_training_on_a_few_minutes_of_motion_says_what_to_expect():
  from chorjax.data.dataset import dataset_notes

  assert not [n for n in dataset_notes(load_dataset(load_config(None).data)) if "minutes of training" in n]
  two = load_dataset(load_config(None, [f"data.val_takes={list(range(2, 10))}"]).data)  # 2 takes trained on
  (note,) = [n for n in dataset_notes(two) if "minutes of training motion" in n]
  minutes = sum(len(m.positions) for m in two.motions if m.name in two.train_names) / two.fps / 60
  assert note.startswith(f"note: {minutes:.1f} minutes") and 0.5 < minutes < 1.5


def test_the_takes_are_read_at_full_float32_precision_on_every_backend(monkeypatch):
  """On a GPU JAX multiplies float32 matrices in TF32 by default: a run trained there had features 4e-4 away
  from the same takes read on a CPU (measured on an H200), and sampling it on a CPU refused its data as
  changed. The reading asks for full precision (a no-op on a CPU, so this checks the request is made)."""
  import jax

  from chorjax.data import dataset

  seen = []
  lengths = dataset.bone_lengths

  def spy(*a, **k):
    seen.append(jax.config.jax_default_matmul_precision)
    return lengths(*a, **k)

  monkeypatch.setattr(dataset, "bone_lengths", spy)
  load_dataset(load_config(None, ["data.seq_length=20"]).data)
  assert seen and set(seen) == {"highest"}
  assert jax.config.jax_default_matmul_precision in (None, "default")  # restored afterwards


def test_one_take_validates_on_its_own_last_frames(tmp_path):
  """``data.val_tail``: a single take (nothing to hold out whole) keeps its last share for validation, a take
  of its own conditioned as the take; the run's held-out takes are those frames (``chorjax eval --data
  held-out``); a take too short for a window on each side is one line."""
  from chorjax.data.dataset import TAIL, dataset_notes
  from chorjax.run import load_run, read_reference
  from chorjax.training.driver import train_and_evaluate

  take = bundled_path("cmu94") / "94_03_skeleton_3d.csv"
  cfg = load_config(None, [f"data.dataset={take}", "data.seq_length=20", "data.val_tail=0.25"])
  ds = load_dataset(cfg.data)
  (whole,) = read_takes([str(take)], cfg.data)
  assert ds.train_names == ("94_03_skeleton_3d",) and ds.val_names == ("94_03_skeleton_3d" + TAIL,)
  assert not [n for n in dataset_notes(ds) if "no validation split" in n]
  (_, head), (_, tail) = ds.train[0], ds.val[0]  # (condition, features): the tail is conditioned as its take
  assert ds.val[0][0] == ds.train[0][0] == 0 and len(head) + len(tail) == whole.num_frames
  assert len(tail) == round(0.25 * whole.num_frames)
  run_dir = tmp_path / "run"
  train_and_evaluate(tiny_config(*[f"data.dataset={take}", "data.val_tail=0.25", "log.tensorboard=false"]), run_dir)
  run = load_run(run_dir)
  assert run.val_loss is not None and run.val_takes == ("94_03_skeleton_3d" + TAIL,)
  held_out, train = read_reference(run, ["held-out"])
  np.testing.assert_array_equal(held_out[0].positions, whole.positions[-len(tail) :])
  assert train[0].num_frames == len(head)
  short = load_config(None, [f"data.dataset={take}", "data.seq_length=500", "data.val_tail=0.1"])
  with pytest.raises(UserError, match=r"94_03_skeleton_3d.csv: \d+ frames; data.val_tail = 0.1 needs at least 1002"):
    load_dataset(short.data)


QUICKSTART = ROOT / "configs" / "quickstart.toml"


def test_takes_that_favour_one_side_are_not_mirrored_under_keep_side(shared_data):
  from chorjax.data.dataset import dataset_notes

  side = lambda ds: [n for n in dataset_notes(ds) if "favour one side" in n]
  cmu94 = load_dataset(load_config(QUICKSTART).data)  # moves both sides alike: mirrored under keep_side
  assert not side(cmu94) and cmu94.augment == ("mirror",)
  assert len(cmu94.train) == 2 * len(load_dataset(load_config(QUICKSTART, ["data.augment=[]"]).data).train)
  cmu131 = [f"data.dataset={shared_data / 'asfamc' / 'cmu131'}", "data.resample_fps=30.0"]
  kept = load_dataset(load_config(QUICKSTART, cmu131).data)  # the quickstart keeps the side
  (note,) = side(kept)
  assert "right_foot moves 2.1x as fast as left_foot" in note and "not mirrored" in note  # CMU 131's right foot
  assert kept.augment == ()
  plain = load_dataset(load_config(QUICKSTART, [*cmu131, "data.augment=[]"]).data)
  assert not side(plain)
  assert all(np.array_equal(a[1], b[1]) for a, b in zip(kept.train, plain.train, strict=True))
  mirrored = load_dataset(load_config(QUICKSTART, [*cmu131, "data.keep_side=false"]).data)
  (note,) = side(mirrored)
  assert "dances them alike" in note and len(mirrored.train) == 2 * len(kept.train)
