"""Pure transforms: exact inverses on every bundled take, mirroring, statistics, jit/vmap."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from chorjax.data import transforms as tf
from chorjax.data.csv import read_csv
from chorjax.data.dataset import resolve_files
from chorjax.data.features import REPRESENTATIONS, Features
from chorjax.data.motion import bone_length_cv

TAKES = [read_csv(f) for f in resolve_files("cmu94")]
SK = TAKES[0].skeleton


def rel_err(a, b):
  a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
  return np.abs(a - b).max() / np.abs(b).max()


@pytest.mark.parametrize("take", TAKES, ids=lambda m: m.name)
def test_round_trips_on_every_take(take):
  pos = jnp.asarray(take.positions)
  assert rel_err(tf.from_bone_relative(tf.to_bone_relative(pos, SK.parents), SK.parents), pos) < 1e-4
  assert rel_err(tf.from_root_relative(tf.to_root_relative(pos, SK.root), SK.root), pos) < 1e-4
  for up in ("y", "-y", "z", "-z", "x", "-x"):
    m = tf.up_axis_matrix(up)
    assert np.isclose(np.linalg.det(m), 1.0)  # a rotation, never a reflection
    assert rel_err(tf.rotate(tf.rotate(pos, m), m.T), pos) < 1e-6
  assert rel_err(tf.scale_units(tf.scale_units(pos, 0.0254), 1 / 0.0254), pos) < 1e-6
  mean, std = pos.reshape(-1, 48).mean(0), pos.reshape(-1, 48).std(0)
  flat = pos.reshape(-1, 48)
  assert rel_err(tf.denormalize(tf.normalize(flat, mean, std), mean, std), flat) < 1e-4
  assert rel_err(tf.reverse_time(tf.reverse_time(pos)), pos) == 0


def test_a_mirrored_copy_favours_the_other_side():
  pos = [np.asarray(t.positions) for t in TAKES]
  joint, ratio = tf.favoured_side(pos, SK.twins)
  assert SK.twins[joint] != joint and ratio >= 1.0
  mirrored = [np.asarray(tf.mirror(p, SK.twins)) for p in pos]
  assert tf.favoured_side(mirrored, SK.twins) == (SK.twins[joint], pytest.approx(ratio, rel=1e-5))
  # the takes and their mirror images together move both sides alike
  assert tf.favoured_side(pos + mirrored, SK.twins)[1] == pytest.approx(1.0, abs=1e-5)


@pytest.mark.parametrize("take", TAKES, ids=lambda m: m.name)
def test_mirror_is_an_involution_that_keeps_bone_lengths(take):
  pos = take.positions
  once = np.asarray(tf.mirror(pos, SK.twins))
  np.testing.assert_array_equal(np.asarray(tf.mirror(once, SK.twins)), pos)
  # each bone of the mirror is as long as its twin bone in the original
  for p, c in SK.bones:
    np.testing.assert_allclose(
      np.linalg.norm(once[:, c] - once[:, p], axis=-1),
      np.linalg.norm(pos[:, SK.twins[c]] - pos[:, SK.twins[p]], axis=-1),
      rtol=1e-6,
    )
  # left and right really swapped: the right foot of the mirror sits where the left one was, x negated
  np.testing.assert_array_equal(once[:, 0, 0], -pos[:, 5, 0])


def test_y_down_becomes_y_up():
  up = np.asarray(tf.rotate(TAKES[0].positions, tf.up_axis_matrix("-y")))
  assert up[:, 9, 1].mean() > up[:, [0, 5], 1].mean()  # head above the feet


def test_merged_statistics_equal_the_pooled_ones():
  arrays = [t.positions.reshape(t.num_frames, -1) for t in TAKES]
  s = tf.merged_stats(arrays)
  pooled = np.concatenate(arrays).astype(np.float64)
  np.testing.assert_allclose(s.mean, pooled.mean(0), rtol=1e-10)
  np.testing.assert_allclose(s.std(ddof=1), pooled.std(0, ddof=1), rtol=1e-10)
  assert s.count == pooled.shape[0]


def test_resample_keeps_samples_on_shared_instants():
  pos = TAKES[6].positions
  up = np.asarray(tf.resample(pos, 30, 60))
  assert up.shape[0] == 2 * pos.shape[0] - 1
  np.testing.assert_allclose(up[::2], pos, rtol=1e-6)
  np.testing.assert_allclose(np.asarray(tf.resample(up, 60, 30)), pos, rtol=1e-6)


def test_transforms_jit_and_vmap():
  batch = jnp.stack([TAKES[i].positions[:500] for i in range(3)])
  f = jax.jit(jax.vmap(lambda p: tf.from_bone_relative(tf.to_bone_relative(p, SK.parents), SK.parents)))
  assert rel_err(f(batch), batch) < 1e-4
  g = jax.jit(jax.vmap(lambda p: tf.mirror(p, SK.twins)))
  np.testing.assert_array_equal(np.asarray(g(batch)), np.asarray(tf.mirror(batch, SK.twins)))


@pytest.mark.parametrize("rep", [r for r in REPRESENTATIONS if r not in ("canonical", "directions")])
def test_features_encode_decode_round_trip(rep):  # the per-frame ones; root-motion ones below
  feats = Features(SK, rep, "-y", 0.01, np.zeros(48, np.float32), np.ones(48, np.float32))
  flat = np.concatenate([np.asarray(feats.represent(feats.canonical(t.positions))) for t in TAKES])
  feats = Features(SK, rep, "-y", 0.01, flat.mean(0), flat.std(0, ddof=1))
  for t in TAKES:
    z = feats.encode(t.positions)
    assert z.shape == (t.num_frames, 48)
    assert rel_err(feats.decode(z), t.positions) < 1e-4
  assert Features.from_dict(feats.to_dict()).to_dict() == feats.to_dict()


def test_bundled_takes_have_rigid_bones():
  for t in TAKES:
    assert np.median(bone_length_cv(t.positions, SK)) <= 0.03


# ---------------------------------------------------------------- root-motion representations


def _features(representation, take):
  """A fitted pipeline of one take (the statistics do not matter for exactness)."""
  from chorjax.data.features import feature_dim

  d = feature_dim(SK, representation)
  lengths = None
  if representation == "directions":
    lengths = np.zeros(SK.num_joints, np.float32)
    lengths[[c for _, c in SK.bones]] = take.bone_lengths().mean(0) * 0.01
  return Features(SK, representation, "-y", 0.01, np.zeros(d, np.float32), np.ones(d, np.float32), lengths)


@pytest.mark.parametrize("take", TAKES, ids=lambda m: m.name)
def test_canonical_features_invert_exactly_given_the_recorded_placement(take):
  from chorjax.data.features import hips

  f = _features("canonical", take)
  canon = f.canonical(take.positions)
  z = f.encode(take.positions)
  assert z.shape == (take.num_frames, 4 + 3 * 15 + 3 * 16 + 2) and bool(jnp.isfinite(z).all())
  place = tf.placement(canon, SK.root, *hips(SK))
  assert rel_err(f.decode(z, place), take.positions) < 1e-4
  # without the placement: the same dance, turned and moved on the floor (heights and shape unchanged)
  loose = np.asarray(f.decode(z))
  np.testing.assert_allclose(loose[..., 1], take.positions[..., 1], atol=1e-2)  # -y up: heights kept
  np.testing.assert_allclose(bone_length_cv(loose, SK), bone_length_cv(take.positions, SK), atol=1e-5)
  contacts = np.asarray(z[:, -2:])
  assert set(np.unique(contacts)) <= {0.0, 1.0} and 0.05 < contacts.mean() < 0.95  # feet on and off the floor


@pytest.mark.parametrize("take", TAKES[:3], ids=lambda m: m.name)
def test_direction_features_keep_directions_and_root_path_and_never_stretch_a_bone(take):
  f = _features("directions", take)
  assert Features.from_dict(f.to_dict()).to_dict() == f.to_dict()  # lengths saved with the run
  back = np.asarray(
    f.decode(f.encode(take.positions), (0.0, *np.asarray(f.canonical(take.positions))[0, SK.root, [0, 2]]))
  )
  assert bone_length_cv(back, SK).max() < 1e-5 < bone_length_cv(take.positions, SK).min()
  unit = lambda p: (
    (b := p - p[:, [max(q, 0) for q in SK.parents]]) / np.maximum(np.linalg.norm(b, axis=-1, keepdims=True), 1e-9)
  )
  np.testing.assert_allclose(
    unit(back)[:, [c for _, c in SK.bones]], unit(take.positions)[:, [c for _, c in SK.bones]], atol=1e-4
  )
  np.testing.assert_allclose(back[:, SK.root], take.positions[:, SK.root], atol=1e-2)


def test_heading_turns_with_the_dancer():
  pos = jnp.asarray(TAKES[0].positions[:1], jnp.float32)
  from chorjax.data.features import hips

  canon = _features("canonical", TAKES[0]).canonical(pos)
  h0 = tf.heading(canon, *hips(SK))
  turned = tf.rotate_y(canon, 0.5)
  np.testing.assert_allclose(tf.heading(turned, *hips(SK)), h0 + 0.5, atol=1e-5)


@pytest.mark.parametrize("take", TAKES[:3], ids=lambda m: m.name)
def test_rigid_bones_sets_every_length_and_keeps_directions_and_root(take):
  pos = np.asarray(take.positions, np.float64)
  lengths = np.zeros(SK.num_joints)
  lengths[[c for _, c in SK.bones]] = take.bone_lengths().mean(0)
  fixed = np.asarray(tf.rigid_bones(pos, SK.parents, lengths))
  assert bone_length_cv(fixed, SK).max() < 1e-5 < bone_length_cv(pos, SK).min()
  np.testing.assert_allclose(fixed[:, SK.root], pos[:, SK.root], rtol=1e-6)
  bones = lambda p: p - p[:, [max(q, 0) for q in SK.parents]]
  cos = np.sum(bones(fixed) * bones(pos), -1) / (
    np.linalg.norm(bones(fixed), axis=-1) * np.linalg.norm(bones(pos), axis=-1) + 1e-12
  )
  assert cos[:, [c for _, c in SK.bones]].min() > 1 - 1e-6  # every bone points where it pointed
  np.testing.assert_allclose(tf.rigid_bones(fixed, SK.parents, lengths), fixed, atol=1e-3)  # idempotent
  # a dancer whose bones do not stretch keeps her pose exactly
  own = np.zeros(SK.num_joints)
  own[[c for _, c in SK.bones]] = take.bone_lengths()[0]
  np.testing.assert_allclose(tf.rigid_bones(pos[:1], SK.parents, own), pos[:1], atol=1e-3)


@pytest.mark.parametrize("take", TAKES[:3], ids=lambda m: m.name)
def test_locked_feet_do_not_slide_and_poses_are_kept(take):
  from chorjax.data.features import leg_length

  canon = np.asarray(_features("canonical", take).canonical(take.positions), np.float64)
  contacts = np.asarray(tf.foot_contacts(canon, SK.feet, leg_length(canon, SK)))
  # a dancer sliding across the floor: every frame moved on by a constant drift
  drift = np.arange(len(canon))[:, None, None] * np.array([0.1, 0.0, 0.05])
  exact = np.asarray(tf.lock_feet(canon + drift, contacts, SK.feet, width=0))  # every frame's slide taken back
  locked = np.asarray(tf.lock_feet(canon + drift, contacts, SK.feet))  # the slide averaged over 17 frames
  root = SK.root
  for out in (exact, locked):
    np.testing.assert_allclose(out - out[:, root : root + 1], canon - canon[:, root : root + 1], atol=1e-4)
    np.testing.assert_allclose(out[..., 1], canon[..., 1], atol=1e-5)  # heights untouched
  held = (contacts[1:] > 0.5) & (contacts[:-1] > 0.5)
  one = held.sum(-1) == 1  # frames with one foot held: exactly locked, it stays exactly where it was
  steps = lambda p: np.linalg.norm(np.diff(p[:, SK.feet][..., [0, 2]], axis=0), axis=-1)
  assert one.sum() > 50 and steps(exact)[one][held[one]].max() < 1e-4
  own, drifted = steps(canon), steps(canon + drift)  # the take's own, undrifted
  assert steps(locked)[held].mean() <= own[held].mean() < 0.5 * drifted[held].mean()  # the drift is gone, and more
  # taken back frame by frame, the feet's tremble shakes the whole body; averaged, the body is as calm as the take
  rough = lambda p: np.linalg.norm(p[2:] - 2 * p[1:-1] + p[:-2], axis=-1).mean()
  assert rough(locked) < 1.05 * rough(canon) < rough(exact)


def test_a_swinging_foot_called_planted_does_not_drag_the_body():
  pos = np.zeros((3, SK.num_joints, 3), np.float32)
  pos[2, SK.feet[0], 0] = 1.0  # the foot swings a whole unit in one frame
  contacts = np.ones((3, len(SK.feet)), np.float32)
  np.testing.assert_allclose(tf.lock_feet(pos, contacts, SK.feet, max_step=0.1), pos)
  assert np.asarray(tf.lock_feet(pos, contacts, SK.feet))[2, SK.root, 0] != 0.0  # uncapped, it would


@pytest.mark.parametrize("take", TAKES[:3], ids=lambda m: m.name)
def test_grounded_feet_stand_on_the_floor_and_a_jump_keeps_its_height(take):
  from chorjax.data.features import floor_height, leg_length

  canon = np.asarray(_features("canonical", take).canonical(take.positions), np.float64)
  contacts = np.asarray(tf.foot_contacts(canon, SK.feet, leg_length(canon, SK)))
  floor = floor_height([canon], SK)
  lowest = lambda p: p[:, list(SK.feet), 1].min(-1)
  # the take itself: its feet in contact are on its floor already, so grounding hardly moves it
  same = np.asarray(tf.ground_feet(canon, contacts, SK.feet, floor))
  assert np.abs(same - canon).max() < 0.1 * leg_length(canon, SK)
  np.testing.assert_allclose(same[..., [0, 2]], canon[..., [0, 2]], atol=1e-5)  # the path over the floor: kept
  # floating: 200 frames carried up half a leg; where a foot is in contact it comes back down
  leg = leg_length(canon, SK)
  up = canon.copy()
  up[100:300, :, 1] += 0.5 * leg
  grounded = np.asarray(tf.ground_feet(up, contacts, SK.feet, floor))
  touching = (contacts[100:300] > 0.5).any(-1)
  assert touching.mean() > 0.5
  ease = tf.GROUND_EASE + 1
  inner = slice(100 + ease, 300 - ease)  # the smoothing window blends the first and last frames of the lift
  err = np.abs(grounded[inner] - same[inner])[..., 1].max(-1)[(contacts[inner] > 0.5).any(-1)]
  # on the floor, eased near lift-offs
  assert np.median(err) < 1e-4 * leg and np.mean(err < 0.01 * leg) > 0.9 and err.max() < 0.05 * leg
  poses = lambda p: p - p[:, SK.root : SK.root + 1]
  np.testing.assert_allclose(poses(grounded), poses(up), atol=1e-5)  # poses and bones untouched
  assert np.abs(np.diff(grounded[:, SK.root, 1] - up[:, SK.root, 1])).max() < 0.25 * leg  # eased, not a jump cut
  # a jump (no foot in contact) keeps its height: the shift before it fades, the dancer is not pulled down
  air = np.zeros_like(contacts)
  jumped = np.asarray(tf.ground_feet(up, air, SK.feet, floor))
  np.testing.assert_allclose(jumped, up, atol=1e-6)
  assert lowest(grounded).std() < lowest(up).std()


@pytest.mark.parametrize("take", TAKES[:2], ids=lambda m: m.name)
def test_paced_grounding_moves_the_root_no_faster_than_the_take_does(take):
  from chorjax.data.features import floor_height, leg_length

  canon = np.asarray(_features("canonical", take).canonical(take.positions), np.float64)
  leg = leg_length(canon, SK)
  contacts = np.asarray(tf.foot_contacts(canon, SK.feet, leg))
  floor = floor_height([canon], SK)
  rise = np.abs(np.diff(canon[:, SK.root, 1])).max()  # the take's own largest vertical root step
  up = canon.copy()
  up[100:300, :, 1] += 0.5 * leg  # a cut: the body lifted half a leg between two frames
  eased = np.asarray(tf.ground_feet(up, contacts, SK.feet, floor))
  paced = np.asarray(tf.ground_feet(up, contacts, SK.feet, floor, root=SK.root, max_rise=rise))
  vertical = lambda p: np.abs(np.diff(p[:, SK.root, 1])).max()
  assert vertical(eased) > 1.5 * rise  # the 5-frame easing alone lets the body rise faster than it ever did
  assert vertical(paced) <= rise + 1e-6
  poses = lambda p: p - p[:, SK.root : SK.root + 1]
  np.testing.assert_allclose(poses(paced), poses(up), atol=1e-5)  # poses and the path over the floor: kept
  np.testing.assert_allclose(paced[..., [0, 2]], up[..., [0, 2]], atol=1e-5)
  # it catches up: once the lift is made good, feet in contact stand where the eased shift puts them
  late = slice(100 + int(np.ceil(0.5 * leg / rise)) + 10, 290)
  touching = (contacts[late] > 0.5).any(-1)
  err = np.abs(paced[late] - eased[late])[..., SK.root, 1][touching]
  assert touching.mean() > 0.5 and np.median(err) < 1e-3 * leg, (late, np.median(err))


def test_a_grounded_decode_lets_no_foot_sink_below_the_floor():
  """``decode(ground=True)``: a dance carried half a leg down for two seconds, swings and jumps included, has
  no foot more than 2% of the leg below the training floor (the quickstart's own samples sank a third of a
  thigh where no foot was in contact), nor do feet drawn a leg lower; the lift is paced as the rest of the
  shift (a CMU 5 sample's root fell at 1.5x the takes' fastest vertical step as a lift let go), and the take
  as it is stays where it was."""
  from helpers import tiny_config

  from chorjax.data.dataset import load_dataset
  from chorjax.data.features import leg_length

  ds = load_dataset(tiny_config("data.representation=canonical").data)
  f, (_, z) = ds.features, ds.train[0]
  real = np.asarray(f.canonical(f.decode(z)))
  leg = leg_length(real, f.skeleton)
  down = np.array(z, copy=True)
  heights = [3, *range(5, 4 + 3 * (f.skeleton.num_joints - 1), 3)]  # the root's and every joint's height
  down[100:160, heights] -= 0.5 * leg / f.std[heights]  # half a leg lower
  feet = list(f.skeleton.feet)
  # the feet alone a leg lower, in no contact: only the lift keeps them from sinking (a model's legs drawn in)
  others = [j for j in range(f.skeleton.num_joints) if j != f.skeleton.root]
  feet_heights, contacts = [5 + 3 * others.index(j) for j in feet], slice(f.dim - len(feet), f.dim)
  reached = np.array(z, copy=True)
  reached[100:160, feet_heights] -= leg / f.std[feet_heights]
  reached[70:190, contacts] = -f.mean[contacts] / f.std[contacts]
  assert f.max_rise is not None
  for frames, most in ((down, 0.02 * leg), (reached, 0.02 * leg), (z, 0.02 * leg)):
    grounded = np.asarray(f.canonical(f.decode(frames, ground=True)))
    assert (f.floor - grounded[:, feet, 1].min(-1)).max() <= most
    # and the lift, made early enough, moves the root no faster than the takes' fastest vertical step
    assert np.abs(np.diff(grounded[:, f.skeleton.root, 1])).max() <= f.max_rise * (1 + 1e-4)
  unlifted = np.asarray(f.canonical(f.decode(down, ground=False)))
  assert (f.floor - unlifted[:, feet, 1].min(-1)).max() > 0.3 * leg  # it did sink before grounding
