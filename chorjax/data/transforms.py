"""Pure transforms on joint positions, each with its exact inverse where one exists.

Every function here takes and returns arrays (``jax.numpy`` or NumPy), has no side effects, and
works under ``jax.jit`` and ``jax.vmap``. Positions are ``[..., T, J, 3]``; features are
``[..., T, D]`` with ``D = 3 * J``.

Normalization statistics are the one exception to "jax.numpy": they are accumulated on the host
in float64 (Chan et al.'s parallel merge of count/mean/M2), once per dataset.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from chorjax.data.motion import topological_order
from chorjax.errors import check_memory

# ---------------------------------------------------------------- normalization statistics


@dataclasses.dataclass(frozen=True)
class Stats:
  """Running statistics of feature columns: count, mean and sum of squared deviations (M2)."""

  count: int
  mean: np.ndarray
  m2: np.ndarray

  @classmethod
  def of(cls, x_TxD) -> Stats:
    x = np.asarray(x_TxD, dtype=np.float64)
    mean = x.mean(axis=0)
    return cls(x.shape[0], mean, ((x - mean) ** 2).sum(axis=0))

  def merge(self, other: Stats) -> Stats:
    """Chan et al.'s pairwise update: exact for any split of the rows."""
    n = self.count + other.count
    delta = other.mean - self.mean
    mean = self.mean + delta * (other.count / n)
    m2 = self.m2 + other.m2 + delta**2 * (self.count * other.count / n)
    return Stats(n, mean, m2)

  def std(self, ddof: int = 1, floor: float = 1e-8) -> np.ndarray:
    return np.sqrt(np.maximum(self.m2 / max(self.count - ddof, 1), floor**2))


def merged_stats(arrays: Sequence[np.ndarray]) -> Stats:
  """Merges per-file statistics of ``[T_i, D]`` arrays into one."""
  stats = [Stats.of(a) for a in arrays]
  out = stats[0]
  for s in stats[1:]:
    out = out.merge(s)
  return out


def normalize(x, mean, std):
  return (x - mean) / std


def denormalize(z, mean, std):
  return z * std + mean


# ---------------------------------------------------------------- skeleton-relative coordinates


def to_bone_relative(pos_TxJx3, parents: Sequence[int]):
  """Root absolute; every other joint as the offset from its parent along the bone."""
  parent_of = np.asarray(parents)
  root = np.flatnonzero(parent_of < 0)
  parent_pos = pos_TxJx3[..., np.where(parent_of < 0, root[0], parent_of), :]
  is_root = (parent_of < 0)[:, None]
  return jnp.where(is_root, pos_TxJx3, pos_TxJx3 - parent_pos)


def ancestor_matrix(parents: Sequence[int]) -> np.ndarray:
  """``A[j, k] = 1`` if joint k is j or one of its ancestors: absolute = A @ bone-relative."""
  j = len(parents)
  a = np.zeros((j, j), np.float32)
  for joint in range(j):
    k = joint
    while k >= 0:
      a[joint, k] = 1.0
      k = parents[k]
  return a


def from_bone_relative(rel_TxJx3, parents: Sequence[int]):
  """Inverse of ``to_bone_relative``: walks the tree by summing offsets along each joint's path."""
  return jnp.einsum("jk,...kc->...jc", ancestor_matrix(parents), rel_TxJx3)


def to_root_relative(pos_TxJx3, root: int):
  """Root absolute; every other joint as the offset from the root."""
  is_root = (np.arange(pos_TxJx3.shape[-2]) == root)[:, None]
  return jnp.where(is_root, pos_TxJx3, pos_TxJx3 - pos_TxJx3[..., root : root + 1, :])


def from_root_relative(rel_TxJx3, root: int):
  is_root = (np.arange(rel_TxJx3.shape[-2]) == root)[:, None]
  return jnp.where(is_root, rel_TxJx3, rel_TxJx3 + rel_TxJx3[..., root : root + 1, :])


# ---------------------------------------------------------------- axes, units, time


def up_axis_matrix(up_axis: str) -> np.ndarray:
  """The rotation taking coordinates whose up axis is ``up_axis`` to y-up.

  A proper rotation (det +1), never a reflection, so left stays left:
  ``-y`` (y down) turns 180 degrees about x; ``z`` turns -90 degrees about x; and so on.
  """
  table = {
    "y": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
    "-y": [[1, 0, 0], [0, -1, 0], [0, 0, -1]],
    "z": [[1, 0, 0], [0, 0, 1], [0, -1, 0]],
    "-z": [[1, 0, 0], [0, 0, -1], [0, 1, 0]],
    "x": [[0, 1, 0], [1, 0, 0], [0, 0, -1]],
    "-x": [[0, -1, 0], [1, 0, 0], [0, 0, 1]],
  }
  if up_axis not in table:
    raise ValueError(f"unknown up axis {up_axis!r}; one of {sorted(table)}")
  return np.asarray(table[up_axis], np.float32)


def to_up_axis(motion, up_axis: str):
  """The same motion expressed with another up axis (a rotation; exact)."""
  if motion.up_axis == up_axis:
    return motion
  m = up_axis_matrix(up_axis).T @ up_axis_matrix(motion.up_axis)
  # in numpy: the matrix holds 0 and +-1 only, so the result is exact either way, and jax would compile the
  # product once per take length (3.6 of the 4.6 s of reading 300 cached Bandai takes)
  positions = np.asarray(motion.positions, np.float32) @ np.asarray(m, np.float32).T
  return motion.replace(positions=positions, up_axis=up_axis)


def to_y_up(pos_Tx_x3, up_axis: str):
  """Positions whose up axis is ``up_axis`` -> the same positions with y up (a rotation)."""
  return rotate(pos_Tx_x3, up_axis_matrix(up_axis))


def rotate(pos_Tx_x3, matrix_3x3):
  """Applies a 3x3 matrix to every point. With ``matrix.T`` it undoes a rotation."""
  return jnp.einsum("ij,...j->...i", matrix_3x3, pos_Tx_x3)


def scale_units(pos, factor: float):
  return pos * factor


def resample(pos_TxJx3, fps_in: float, fps_out: float, where: str = "resampling"):
  """Linear interpolation in time to another frame rate (first frame kept; no exact inverse). Refused in one
  line, before anything is allocated, when the frames it would make do not fit in memory."""
  t_in = pos_TxJx3.shape[-3]
  t_out = int(np.floor((t_in - 1) * fps_out / fps_in)) + 1
  per_frame = int(np.prod(pos_TxJx3.shape[:-3], dtype=np.int64)) * pos_TxJx3.shape[-2] * 3 * 4 + 24
  check_memory(
    t_out * per_frame, f"{where}: {t_in:,} frames at {fps_in:g} fps resampled to {fps_out:g} fps ({t_out:,} frames)"
  )
  src = np.arange(t_out) * (fps_in / fps_out)
  lo = np.minimum(np.floor(src).astype(np.int32), t_in - 1)
  hi = np.minimum(lo + 1, t_in - 1)
  w = (src - lo).astype(np.float32)[:, None, None]
  return pos_TxJx3[..., lo, :, :] * (1 - w) + pos_TxJx3[..., hi, :, :] * w


# ---------------------------------------------------------------- augmentations


def reverse_time(x, time_axis: int = 0):
  """The motion played backwards (its own inverse)."""
  return jnp.flip(x, axis=time_axis)


def mirror(pos_TxJx3, twins: Sequence[int], lateral_axis: int = 0):
  """Left/right mirror: swap twin joints and negate the lateral axis (its own inverse)."""
  sign = np.ones(3, np.float32)
  sign[lateral_axis] = -1.0
  return pos_TxJx3[..., np.asarray(twins), :] * sign


def favoured_side(takes, twins: Sequence[int]) -> tuple[int, float]:
  """``(joint, ratio)``: of the twin joints, the one whose mean speed per frame over ``takes`` (``[T, J, 3]``
  each, every frame counted once) is furthest above its twin's, and that ratio (1 for a dancer whose sides move
  alike; a mirrored copy of the takes turns it into the twin's)."""
  speed = np.concatenate([np.linalg.norm(np.diff(np.asarray(t), axis=0), axis=-1) for t in takes]).mean(0)
  ratios = speed / np.maximum(speed[np.asarray(twins)], 1e-12)
  joint = int(np.argmax(np.where(np.arange(len(twins)) != np.asarray(twins), ratios, 0.0)))
  return joint, float(ratios[joint])


# ---------------------------------------------------------------- canonical and bone-direction features
# Both take y-up, scaled positions [T, J, 3] of a whole sequence and return per-frame features [T, F];
# the inverses integrate the root's motion along time, so they need the whole sequence too.


def rotate_y(v_x3, angle):
  """Rotates vectors ``[..., 3]`` about the up (y) axis by ``angle`` (radians, broadcast over ``...``)."""
  c, s = jnp.cos(angle), jnp.sin(angle)
  x, y, z = v_x3[..., 0], v_x3[..., 1], v_x3[..., 2]
  return jnp.stack([c * x + s * z, y, -s * x + c * z], -1)


def heading(pos_TxJx3, left: int, right: int):
  """``[T]`` the facing angle about y (0 = facing +z), from the right-to-left hip axis: forward = left x up."""
  across = pos_TxJx3[..., left, :] - pos_TxJx3[..., right, :]
  return jnp.arctan2(-across[..., 2], across[..., 0])


def _wrap(angle):
  return (angle + jnp.pi) % (2 * jnp.pi) - jnp.pi


def _step_back(x_Tx):
  """``x[t] - x[t-1]`` with 0 at t = 0."""
  return jnp.concatenate([jnp.zeros_like(x_Tx[:1]), x_Tx[1:] - x_Tx[:-1]], 0)


def _previous_frame(x_Tx):
  return jnp.concatenate([x_Tx[:1], x_Tx[:-1]], 0)


def foot_contacts(pos_TxJx3, feet: Sequence[int], leg: float):
  """``[T, len(feet)]`` 1 where a foot is near the floor (its 10th height percentile + 0.1 leg) and
  slower than 0.05 leg lengths per frame, else 0."""
  f = pos_TxJx3[:, jnp.asarray(feet)]
  floor = jnp.percentile(f[..., 1], 10)
  speed = jnp.linalg.norm(_step_back(f), axis=-1)
  return ((f[..., 1] < floor + 0.1 * leg) & (speed < 0.05 * leg)).astype(jnp.float32)


def placement(pos_TxJx3, root: int, left: int, right: int):
  """``(heading, x, z)`` of the first frame: the rigid placement the canonical features leave out."""
  return jnp.stack([heading(pos_TxJx3[:1], left, right)[0], pos_TxJx3[0, root, 0], pos_TxJx3[0, root, 2]])


# jitted: run op by op, every take length compiled each of some forty operations anew (20 s for cmu94's ten
# takes); as one program, one compile per length.
@functools.partial(jax.jit, static_argnames=("root", "left", "right", "feet"))
def to_canonical(pos_TxJx3, root: int, left: int, right: int, feet: Sequence[int], leg: float):
  """HumanML3D-style features ``[T, 4 + 3(J-1) + 3J + len(feet)]`` per frame t:

  the change of heading since t-1 (1), the root's horizontal step since t-1 in the facing frame of
  t-1 (2), the root's height (1), every other joint relative to the root's floor point in the facing
  frame of t (3(J-1)), every joint's step since t-1 in the facing frame of t-1 (3J), foot contacts.
  Frame 0's changes are 0. :func:`from_canonical` inverts it exactly given :func:`placement`.
  """
  theta = heading(pos_TxJx3, left, right)
  r = pos_TxJx3[:, root]
  floor_point = r * jnp.array([1.0, 0.0, 1.0])
  local = rotate_y(pos_TxJx3 - floor_point[:, None], -theta[:, None])
  prev_theta = _previous_frame(theta)
  step = rotate_y(_step_back(r), -prev_theta)
  vel = rotate_y(_step_back(pos_TxJx3), -prev_theta[:, None])
  others = jnp.asarray([j for j in range(pos_TxJx3.shape[-2]) if j != root])
  parts = [
    _wrap(_step_back(theta))[:, None],
    step[:, [0, 2]],
    r[:, 1:2],
    local[:, others].reshape(len(r), -1),
    vel.reshape(len(r), -1),
    foot_contacts(pos_TxJx3, feet, leg),
  ]
  return jnp.concatenate(parts, -1)


def from_canonical(feat_xTxF, root: int, num_joints: int, place=None):
  """Positions ``[..., T, J, 3]`` from :func:`to_canonical` features, by integrating the heading and
  the root's steps from ``place = (heading, x, z)`` of frame 0 (default: facing +z at the origin; ``[..., 3]``:
  one place per sequence). Joint velocities and foot contacts are not used."""
  place = jnp.zeros(3) if place is None else jnp.asarray(place)
  d_theta, step_xz, height = feat_xTxF[..., 0], feat_xTxF[..., 1:3], feat_xTxF[..., 3]
  theta = place[..., 0:1] + jnp.cumsum(d_theta, -1)
  prev_theta = jnp.concatenate([jnp.broadcast_to(place[..., 0:1], theta[..., :1].shape), theta[..., :-1]], -1)
  step = jnp.stack([step_xz[..., 0], jnp.zeros_like(height), step_xz[..., 1]], -1)
  start = jnp.stack([place[..., 1], jnp.zeros_like(place[..., 1]), place[..., 2]], -1)[..., None, :]
  floor_point = jnp.cumsum(rotate_y(step, prev_theta), -2) + start
  others = feat_xTxF[..., 4 : 4 + 3 * (num_joints - 1)].reshape(feat_xTxF.shape[:-1] + (num_joints - 1, 3))
  root_local = jnp.stack([jnp.zeros_like(height), height, jnp.zeros_like(height)], -1)[..., None, :]
  local = jnp.concatenate([others[..., :root, :], root_local, others[..., root:, :]], -2)
  return rotate_y(local, theta[..., None]) + floor_point[..., None, :]


@functools.partial(jax.jit, static_argnames=("parents",))
def to_directions(pos_TxJx3, parents: Sequence[int]):
  """``[T, 3 + 3J]``: the root's step since t-1 (0 at t = 0), then per joint the unit direction of its
  bone from the parent (the root's entry holds its height and two zeros). Lengths are left out."""
  p = jnp.asarray(parents)
  root = int(np.flatnonzero(np.asarray(parents) < 0)[0])
  bone = pos_TxJx3 - pos_TxJx3[:, jnp.where(p < 0, root, p)]
  unit = bone / jnp.maximum(jnp.linalg.norm(bone, axis=-1, keepdims=True), 1e-9)
  height = pos_TxJx3[:, root, 1]
  unit = unit.at[:, root].set(jnp.stack([jnp.zeros_like(height), height, jnp.zeros_like(height)], -1))
  return jnp.concatenate([_step_back(pos_TxJx3[:, root]), unit.reshape(len(height), -1)], -1)


def from_directions(feat_xTxF, parents: Sequence[int], lengths_J, start_xz=(0.0, 0.0)):
  """Positions from :func:`to_directions` features: the root integrated from ``start_xz`` (``[..., 2]``: one
  start per sequence; its height as given), each joint its parent plus ``lengths[j]`` times its (renormalized)
  direction. Bones cannot stretch."""
  num_joints = len(parents)
  root = int(np.flatnonzero(np.asarray(parents) < 0)[0])
  step = feat_xTxF[..., :3]
  dirs = feat_xTxF[..., 3:].reshape(feat_xTxF.shape[:-1] + (num_joints, 3))
  height = dirs[..., root, 1]
  start = jnp.asarray(start_xz, step.dtype)
  root_xz = (
    jnp.cumsum(step, -2) + jnp.stack([start[..., 0], jnp.zeros_like(start[..., 0]), start[..., 1]], -1)[..., None, :]
  )
  root_pos = root_xz * jnp.array([1.0, 0.0, 1.0]) + jnp.stack(
    [jnp.zeros_like(height), height, jnp.zeros_like(height)], -1
  )
  return _build(root_pos, dirs, parents, lengths_J)


def rigid_bones(pos_xTxJx3, parents: Sequence[int], lengths_J):
  """The same poses with every bone at ``lengths[j]``: each bone keeps its direction from its parent,
  the root stays where it is (built from the root outwards)."""
  p = np.asarray(parents)
  root = int(np.flatnonzero(p < 0)[0])
  bones = pos_xTxJx3 - pos_xTxJx3[..., np.where(p < 0, root, p), :]
  return _build(pos_xTxJx3[..., root, :], bones, parents, lengths_J)


LOCK_EASE = 8  # frames either side over which lock_feet averages the slide it takes back
GROUND_EASE = 8  # frames either side over which ground_feet averages its shift


def ease(a_xT, width: int):
  """``a`` averaged over time (the last axis) through a Hann window of ``2 * width + 1`` frames, the ends
  held (edge padded): a constant stays as it was; a one-frame spike spreads out."""
  if width == 0:
    return a_xT
  w = np.hanning(2 * width + 3)[1:-1]
  w = w / w.sum()
  shifted = _around(a_xT, width)
  out = jnp.zeros_like(shifted[0])
  for weight, frames in zip(w, shifted):
    out = out + float(weight) * frames
  return out


def _around(a_xT, width: int) -> list:
  """The ``2 * width + 1`` copies of ``a`` shifted by ``-width .. width`` frames (the last axis), its ends held."""
  n = a_xT.shape[-1]
  padded = jnp.pad(a_xT, [(0, 0)] * (a_xT.ndim - 1) + [(width, width)], mode="edge")
  return [padded[..., i : i + n] for i in range(2 * width + 1)]


def lock_feet(pos_xTxJx3, contacts_xTxF, feet: Sequence[int], max_step: float = float("inf"), width: int = LOCK_EASE):
  """The dance moved on the floor so that feet in contact do not drift: at each frame where feet are in
  contact (> 0.5) both then and one frame before, and moved less than ``max_step`` horizontally (a
  faster foot is swinging, whatever the contact says), their mean horizontal step is their slide; the slide,
  averaged over ``2 * width + 1`` frames (:func:`ease`), is taken back from every joint, accumulated over
  time. Averaged, a foot's tremble stays its own instead of shaking the whole body (taken back frame by
  frame, it shakes the real takes' own decode), while a slide that lasts is taken back
  whole. Poses and bone lengths are unchanged; the body then travels by what its legs do (frames without
  contact keep their own root motion); ``width = 0``: every frame's slide exactly."""
  f = pos_xTxJx3[..., jnp.asarray(feet), :]
  step = (f[..., 1:, :, :] - f[..., :-1, :, :]) * jnp.array([1.0, 0.0, 1.0])
  held = (contacts_xTxF[..., 1:, :] > 0.5) & (contacts_xTxF[..., :-1, :] > 0.5)
  held = jnp.where(held & (jnp.linalg.norm(step, axis=-1) < max_step), 1.0, 0.0)
  slide = jnp.sum(held[..., None] * step, -2) / jnp.maximum(jnp.sum(held, -1), 1.0)[..., None]
  back = -jnp.cumsum(jnp.moveaxis(ease(jnp.moveaxis(slide, -1, -2), width), -1, -2), -2)
  return pos_xTxJx3 + jnp.concatenate([jnp.zeros_like(back[..., :1, :]), back], -2)[..., None, :]


def ground_feet(
  pos_xTxJx3,
  contacts_xTxF,
  feet: Sequence[int],
  floor: float,
  hold: float = 0.9,
  width: int = GROUND_EASE,
  root: int | None = None,
  max_rise: float | None = None,
  sink: float | None = None,
):
  """The dance moved up or down so that a foot in contact stands on the floor (y-up positions): at each frame
  where feet are in contact (> 0.5) the body is shifted by ``floor`` minus the lowest such foot's height;
  frames without contact (a jump, a swing) keep the last shift, fading by ``hold`` per frame, and the shift
  is averaged over ``2 * width + 1`` frames (:func:`ease`) so that it neither jumps nor passes a foot's
  tremble to the body. Poses, bone lengths and the horizontal path are unchanged. A model whose feet float
  above (or sink into) the floor where it says they touch it dances on the floor. With ``sink``, no foot ends
  more than that below the floor, contact or not (where one would, the body is lifted by the most any frame
  within ``width // 2`` needs, averaged over as many). With ``root`` and ``max_rise`` (the training takes'
  largest vertical root step per frame) the shift follows at the pace the dancer could: no frame moves the
  root up or down by more than ``max_rise`` (where the shift alone would, it catches up over the next frames
  instead), the lift that ``sink`` asks for included: it starts as early as that pace needs."""
  return _ground_feet(pos_xTxJx3, contacts_xTxF, tuple(feet), floor, hold, width, root, max_rise, sink)


# Compiled once per shape: called eagerly, each call's scan bodies (new closures) compiled anew, and
# calibration, which grounds 180 drawn dances, spent most of its time compiling them.
@functools.partial(jax.jit, static_argnames=("feet", "width", "root"))
def _ground_feet(pos_xTxJx3, contacts_xTxF, feet, floor, hold, width, root, max_rise, sink):
  y = pos_xTxJx3[..., jnp.asarray(feet), 1]
  on = contacts_xTxF > 0.5
  touching = on.any(-1)
  target = jnp.where(touching, floor - jnp.min(jnp.where(on, y, jnp.inf), -1), 0.0)

  def step(previous, frame):
    want, touch = frame
    shift = jnp.where(touch, want, hold * previous)
    return shift, shift

  time_first = lambda a: jnp.moveaxis(a, -1, 0)
  _, shift = jax.lax.scan(step, jnp.zeros(target.shape[:-1], target.dtype), (time_first(target), time_first(touching)))
  shift = jnp.moveaxis(shift, 0, -1)
  eased = ease(shift, width)
  least = None if sink is None else floor - sink - jnp.min(y, -1)  # the shift below which a foot sinks too far
  if least is not None:  # no foot further below the floor than that, wherever the shift left it
    lift = jnp.maximum(least - eased, 0.0)
    eased = eased + _box(_box(lift, width // 2, jnp.max), width // 2, jnp.mean)  # >= every frame's own lift
  if root is not None and max_rise is not None:
    own = pos_xTxJx3[..., root, 1]
    # the root's lowest height: where a foot would sink, lifted early enough to be made at the dancer's pace
    low = jnp.full_like(own, -jnp.inf) if least is None else _envelope(own + least, max_rise)

    def paced(last, frame):  # last: the shifted root's height one frame before
      want, lowest = frame
      height = jnp.clip(jnp.maximum(want, lowest), last - max_rise, last + max_rise)
      return height, height

    want, low = time_first(own + eased), time_first(low)
    _, height = jax.lax.scan(paced, jnp.maximum(want[0], low[0]), (want, low))
    eased = jnp.moveaxis(height, 0, -1) - own
  return pos_xTxJx3 + eased[..., None, None] * jnp.array([0.0, 1.0, 0.0])


def _envelope(low_xT, rate):
  """The least heights ``>= low`` (time the last axis) that change by at most ``rate`` a frame: ``low``'s
  peaks widened into ramps either side, so that a body paced at ``rate`` reaches each in time."""

  def ahead(last, a):
    height = jnp.maximum(a, last - rate)
    return height, height

  low_Tx = jnp.moveaxis(low_xT, -1, 0)
  _, forward = jax.lax.scan(ahead, low_Tx[0], low_Tx)
  _, both = jax.lax.scan(ahead, forward[-1], forward, reverse=True)
  return jnp.moveaxis(both, 0, -1)


def _box(a_xT, width: int, reduce):
  """``reduce`` over the ``2 * width + 1`` frames around each (the last axis; ends held)."""
  return reduce(jnp.stack(_around(a_xT, width)), 0)


def _build(root_pos, dirs_xJx3, parents: Sequence[int], lengths_J):
  """Joint positions from the root's and, per joint, the direction of its bone (renormalized)."""
  root = int(np.flatnonzero(np.asarray(parents) < 0)[0])
  unit = dirs_xJx3 / jnp.maximum(jnp.linalg.norm(dirs_xJx3, axis=-1, keepdims=True), 1e-9)
  joints = {root: root_pos}
  for j in topological_order(parents):  # parents before children
    if j != root:
      joints[j] = joints[parents[j]] + lengths_J[j] * unit[..., j, :]
  return jnp.stack([joints[j] for j in range(len(parents))], -2)
