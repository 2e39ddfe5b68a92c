"""The fitted feature pipeline: data-space joint positions <-> normalized model features.

encode: rotate to y-up -> scale units -> representation (absolute / bone-relative /
root-relative) -> flatten ``[T, J*3]`` -> normalize with training-split statistics.
decode is the exact inverse, so a sample comes back in the data's own units and axes.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from chorjax.data import transforms
from chorjax.data.joint_names import split_name
from chorjax.data.motion import Skeleton, chain_length, mean_bone_lengths
from chorjax.errors import UserError

REPRESENTATIONS = ("absolute", "bone_relative", "root_relative", "canonical", "directions")


class JointMotion(NamedTuple):
  """What :func:`joint_pace` needs of canonical features: their normalization ``mean``, ``std`` ``[D]`` and
  the channels of every joint but the root, ``joints`` ``[J - 1, 3]``."""

  mean: np.ndarray
  std: np.ndarray
  joints: np.ndarray


def joint_pace(now_xD, then_xD, turn_x, m: JointMotion):
  """How far the joints move relative to the root from canonical frame ``then`` to ``now`` (normalized),
  the dancer having turned by ``turn`` radians between them: the mean over all joints (the root's is 0) of
  ``|R(turn) q(now) - q(then)|``, ``q`` a joint relative to the root in the facing frame (scaled, y-up).
  What ``metrics.displacement`` measures on positions, turning included: a dancer who spins moves."""

  def relative(z):  # [..., J - 1, 3]
    pos = z[..., m.joints] * m.std[m.joints] + m.mean[m.joints]  # above the root's floor point
    height = z[..., 3] * m.std[3] + m.mean[3]  # the root's (canonical channel 3)
    return pos - height[..., None, None] * jnp.array([0.0, 1.0, 0.0])

  moved = transforms.rotate_y(relative(now_xD), jnp.asarray(turn_x)[..., None]) - relative(then_xD)
  return jnp.linalg.norm(moved, axis=-1).sum(-1) / (m.joints.shape[0] + 1)


def take_joint_pace(z_TxD, lag: int, m: JointMotion) -> np.ndarray:
  """:func:`joint_pace` of a whole take (normalized canonical frames ``[T, D]``) at every frame ``lag`` frames
  after another, ``[T - lag]``: the turn between them summed from the heading changes (channel 0)."""
  return takes_joint_pace([z_TxD], lag, m)[0]


PACE_CHUNK = 1 << 15  # frame pairs a call of takes_joint_pace: one shape, one compile, bounded memory


def takes_joint_pace(takes, lag: int, m: JointMotion) -> list[np.ndarray]:
  """:func:`take_joint_pace` of each take in ``takes``, computed over all their frame pairs ``PACE_CHUNK`` at a
  time (one program for every take's length, and no copy of a library's hours of frames at once)."""
  dim = takes[0].shape[-1]
  now, then, turn = (
    np.zeros((PACE_CHUNK, dim), np.float32),
    np.zeros((PACE_CHUNK, dim), np.float32),
    np.zeros(PACE_CHUNK, np.float32),
  )
  buffers = (now, then, turn)
  out, filled, lengths = [], 0, []
  for z_TxD in takes:
    turned = np.cumsum(z_TxD[:, 0] * m.std[0] + m.mean[0])
    parts = (z_TxD[lag:], z_TxD[:-lag], turned[lag:] - turned[:-lag])
    lengths.append(len(parts[2]))
    done = 0
    while done < lengths[-1]:
      k = min(PACE_CHUNK - filled, lengths[-1] - done)
      for buffer, part in zip(buffers, parts):
        buffer[filled : filled + k] = part[done : done + k]
      filled, done = filled + k, done + k
      if filled == PACE_CHUNK:
        out.append(np.asarray(joint_pace(now, then, turn, m)))
        filled = 0
  if filled:
    out.append(np.asarray(joint_pace(now, then, turn, m))[:filled])  # the rest of the buffer: the last chunk's, unused
  return np.split(np.concatenate(out), np.cumsum(lengths)[:-1])


@dataclasses.dataclass(frozen=True, eq=False)
class Features:
  """Everything needed to map positions to model features and back.

  Attributes:
    skeleton: the joint tree.
    representation: one of ``REPRESENTATIONS``.
    up_axis: the signed up axis of the data space (rotated to y-up inside).
    scale: multiplies lengths before the representation (e.g. to metres).
    mean, std: ``[D]`` normalization statistics of the training split (ddof=1).
    lengths: ``[J]`` bone length of each joint from its parent, the training takes' mean (the
      ``directions`` representation builds every frame with these, and ``decode(z, rigid=True)`` sets
      any representation's bones to them: bones cannot stretch).
    low, high: ``[D]`` the smallest and largest normalized value of each feature over the training
      split (mirrored copies included); generation can clip to them (``sample.clamp``).
    pace_lag, pace: how far the training frames' pose moves in ``pace_lag`` frames (half a second): the
      mean absolute change of the normalized ``pose_channels`` over that lag; generation can hold its
      own pace to it (``sample.pace``).
    pace_joints: canonical runs: the same as the judge measures it (:func:`joint_pace`: joints relative
      to the root, turning included, scaled units); where it is known the governor holds this instead.
    pace_by_label: runs conditioned on labels (``data.labels``): the pace of each label combination of the
      training takes, ``[K, M + 1]`` (its weights ``[M]``, the log of its takes' pace in the governor's
      measure); the governor holds each dancer to the pace of the labels it dances
      (``controls.Pacing.for_motion``).
    step_low, step_high: ``[D]`` the smallest and largest change of each normalized feature from one frame
      to the next over the training split; generation can hold each frame's change to them
      (``sample.clamp_steps``).
    floor: the height of the floor in the training takes (y-up, scaled: the median height of the lowest
      foot; canonical runs), where ``decode(z, ground=True)`` puts feet in contact.
    scale_ceiling: ``[S]`` the model's own MDN scale ceiling for ``sample.scale_cap`` (measured on the
      training frames when sampling asks for it, ``run.with_ceiling``; not saved with the run).

  Representations: ``absolute``, ``bone_relative`` and ``root_relative`` are per-frame ``[J, 3]``;
  ``canonical`` (HumanML3D-style: heading change, root step in the facing frame, root height, joints
  in the facing frame, joint steps, foot contacts) and ``directions`` (root step, root height, unit
  bone directions) describe the root by its motion, which decoding integrates from the first frame's
  placement (``decode(z, place)``; default: at the origin, facing +z).
  """

  skeleton: Skeleton
  representation: str
  up_axis: str
  scale: float
  mean: np.ndarray
  std: np.ndarray
  lengths: np.ndarray | None = None
  low: np.ndarray | None = None
  high: np.ndarray | None = None
  pace_lag: int | None = None
  pace: float | None = None
  pace_joints: float | None = None
  pace_by_label: np.ndarray | None = None
  floor: float | None = None
  step_low: np.ndarray | None = None
  step_high: np.ndarray | None = None
  scale_ceiling: np.ndarray | None = None

  @property
  def dim(self) -> int:
    return feature_dim(self.skeleton, self.representation)

  @property
  def max_rise(self) -> float | None:
    """The training takes' largest vertical root step per frame (canonical runs that record their steps;
    y-up, scaled): how fast ``decode(ground=True)`` may move the body up or down."""
    if self.representation != "canonical" or self.step_low is None or self.step_high is None:
      return None
    return float(max(-self.step_low[3], self.step_high[3]) * self.std[3])

  @property
  def pose_channels(self) -> np.ndarray:
    """Indices of the features that hold the pose (joint positions or bone directions, not root motion,
    velocities or contacts): what the pace governor measures, as the movement metric measures joints."""
    j = self.skeleton.num_joints
    if self.representation == "canonical":
      return np.arange(4, 4 + 3 * (j - 1))
    if self.representation == "directions":
      return np.arange(3, 3 + 3 * j)
    return np.arange(3 * j)

  @property
  def joint_motion(self) -> JointMotion | None:
    """What :func:`joint_pace` needs of these features (canonical ones; else None)."""
    if self.representation != "canonical":
      return None
    joints = self.pose_channels.reshape(-1, 3)
    return JointMotion(np.asarray(self.mean, np.float32), np.asarray(self.std, np.float32), joints)

  def canonical(self, pos_TxJx3):
    """Data space -> y-up, scaled positions (before the representation)."""
    return transforms.scale_units(transforms.to_y_up(pos_TxJx3, self.up_axis), self.scale)

  def uncanonical(self, pos_TxJx3):
    return _uncanonical(pos_TxJx3, self.up_axis, 1.0 / self.scale)

  def represent(self, canon_TxJx3):
    """Canonical positions -> un-normalized flat features ``[T, D]``."""
    rep = _represent(canon_TxJx3, self.skeleton, self.representation)
    return rep.reshape(canon_TxJx3.shape[:-2] + (self.dim,))

  def encode(self, pos_TxJx3):
    """Data-space positions ``[..., T, J, 3]`` -> normalized features ``[..., T, D]``."""
    return transforms.normalize(self.represent(self.canonical(pos_TxJx3)), self.mean, self.std)

  def decode(self, z_TxD, place=None, rigid: bool = False, lock_feet: bool = False, ground: bool = False):
    """Normalized features ``[..., T, D]`` -> data-space positions ``[..., T, J, 3]`` (``place``: the
    first frame's ``(heading, x, z)`` for the representations that integrate the root's motion;
    ``rigid``: every bone at the training takes' mean length, see ``transforms.rigid_bones``;
    ``lock_feet``: feet the features call in contact do not slide, see ``transforms.lock_feet``;
    ``ground``: feet the features call in contact stand on the training floor, see ``transforms.ground_feet``)."""
    self.check_decode(rigid, lock_feet, ground=ground)
    floor = 0.0 if self.floor is None else self.floor
    statics = {"representation": self.representation, "skeleton": self.skeleton, "up_axis": self.up_axis}
    pos = _decoded(
      z_TxD,
      self.mean,
      self.std,
      place,
      self.lengths,
      floor,
      1.0 / self.scale,
      self.max_rise,
      **statics,
      rigid=rigid,
      ground=ground,
      finish=not lock_feet,
    )
    if not lock_feet:
      return pos
    leg = leg_length(np.asarray(pos).reshape(-1, *pos.shape[-2:]), self.skeleton)
    return _locked(pos, z_TxD, self.mean, self.std, 0.05 * leg, 1.0 / self.scale, **statics)  # foot_contacts' speed

  def decode_frame(self, z_BxD, place_Bx3, rigid: bool = False):
    """One frame of each of B dancers -> ``(positions [B, J, 3] in data space, the next frame's place [B, 3])``:
    :meth:`decode` one frame at a time, the place (heading, x, z of the root on the floor: see
    ``transforms.from_canonical``; zeros at a dancer's first frame) carried from call to call. Frame by frame
    these are the positions :meth:`decode` gives the whole sequence with ``rigid`` (its feet neither grounded nor
    locked: those look at every frame). Traceable: the exported dancer decodes in its graph."""
    rep = transforms.denormalize(z_BxD, self.mean, self.std)[:, None, :]
    root = self.skeleton.root
    canon = _unrepresent(rep, self.representation, self.skeleton, self.lengths, place_Bx3)[:, 0]
    place = place_Bx3  # the representations that place every frame themselves carry nothing
    if self.representation in ("canonical", "directions"):  # they integrate the root: where it got to
      turned = place_Bx3[:, 0] + rep[:, 0, 0] if self.representation == "canonical" else place_Bx3[:, 0]
      place = jnp.stack([turned, canon[:, root, 0], canon[:, root, 2]], -1)
    if rigid:
      canon = transforms.rigid_bones(canon, self.skeleton.parents, self.lengths)
    return self.uncanonical(canon), place

  def decode_after(
    self, z_TxD, last_z_D, last_pos_Jx3, rigid: bool = False, lock_feet: bool = False, ground: bool = False
  ):
    """Frames that follow one already decoded (normalized ``last_z_D``, at data-space ``last_pos_Jx3``)
    -> data-space positions ``[T, J, 3]`` that continue from it: decoded with that frame as their frame
    0, then turned about the up axis and moved over the floor (the representations that integrate the
    root's motion) so that frame 0 lands where it was. A stream decodes chunk by chunk this way
    (``chorjax live``); the other representations place every frame themselves."""
    z = np.concatenate([np.asarray(last_z_D)[None], np.asarray(z_TxD)], 0)
    pos = self.canonical(self.decode(z, rigid=rigid, lock_feet=lock_feet, ground=ground))
    if self.representation in ("canonical", "directions"):
      target = self.canonical(np.asarray(last_pos_Jx3))
      turn = 0.0
      if self.representation == "canonical":  # directions hold absolute bone directions: no heading to fix
        left, right = hips(self.skeleton)
        turn = transforms.heading(target, left, right) - transforms.heading(pos[0], left, right)
      floor = lambda p: p[self.skeleton.root] * jnp.array([1.0, 0.0, 1.0])
      pos = transforms.rotate_y(pos - floor(pos[0]), turn) + floor(target)
    return np.asarray(self.uncanonical(pos[1:]), np.float32)

  def check_decode(self, rigid: bool = False, lock_feet: bool = False, ground: bool = False) -> None:
    """Raises ValueError if :meth:`decode` cannot do what is asked (callers check before long work; the draw's
    own needs: ``Controls.draw``)."""
    if rigid and self.lengths is None:
      raise ValueError("rigid_bones: this run records no bone lengths (trained before the option existed)")
    if lock_feet and self.representation != "canonical":
      raise ValueError(f"foot_lock: needs data.representation = canonical (this run: {self.representation})")
    if ground and self.representation != "canonical":
      raise ValueError(f"ground: needs data.representation = canonical (this run: {self.representation})")
    if ground and self.floor is None:
      raise ValueError("ground: this run records no floor height (Run.ranged measures it on the training takes)")

  def to_dict(self) -> dict:
    return {
      "skeleton": self.skeleton.to_dict(),
      "representation": self.representation,
      "up_axis": self.up_axis,
      "scale": self.scale,
      "mean": np.asarray(self.mean).tolist(),
      "std": np.asarray(self.std).tolist(),
      **{k: np.asarray(v).tolist() for k, v in self._optional().items() if v is not None},
    }

  def _optional(self) -> dict:
    ranges = {k: getattr(self, k) for k in (*self.RANGES, *self.STEPS)}
    paces = {"pace_lag": self.pace_lag, "pace": self.pace, "pace_joints": self.pace_joints}
    paces["pace_by_label"] = self.pace_by_label
    return {"lengths": self.lengths, **ranges, **paces, "floor": self.floor}

  RANGES = ("low", "high")
  STEPS = ("step_low", "step_high")

  @classmethod
  def from_dict(cls, d: dict) -> Features:
    return cls(
      Skeleton.from_dict(d["skeleton"]),
      d["representation"],
      d["up_axis"],
      float(d["scale"]),
      np.asarray(d["mean"], np.float32),
      np.asarray(d["std"], np.float32),
      **{k: None if d.get(k) is None else np.asarray(d[k], np.float32) for k in ("lengths", *cls.RANGES, *cls.STEPS)},
      pace_lag=None if d.get("pace_lag") is None else int(d["pace_lag"]),
      pace=None if d.get("pace") is None else float(d["pace"]),
      pace_joints=None if d.get("pace_joints") is None else float(d["pace_joints"]),
      pace_by_label=None if d.get("pace_by_label") is None else np.asarray(d["pace_by_label"], np.float32),
      floor=None if d.get("floor") is None else float(d["floor"]),
    )


def floor_height(canon_takes, skeleton: Skeleton) -> float:
  """The floor of y-up takes: the median height of each frame's lowest foot (``Features.floor``)."""
  feet = list(skeleton.feet)
  return float(np.median(np.concatenate([np.asarray(c)[:, feet, 1].min(-1) for c in canon_takes])))


# Frames whose float64 copy fits in this many entries (256 MB) get numpy's covariance over all of them at
# once; a library's millions of frames are summed take by take instead (the same covariance to float64's last
# bits, without three whole copies of the training set).
COVARIANCE_IN_ONE = 1 << 25


def principal_axes(frames) -> np.ndarray:
  """``[D, D]`` orthogonal: the principal axes of the frames (columns, most variance first, each signed so
  that its largest entry is positive): the MDN's coordinates under ``model.mdn_basis = "pca"`` (of the frames)
  and ``"acceleration"`` (of their second differences). ``frames``: one ``[N, D]`` array or a sequence of them
  (a run's training takes)."""
  takes = [np.asarray(frames)] if isinstance(frames, np.ndarray) else [np.asarray(t) for t in frames]
  n = sum(len(t) for t in takes)
  if any(t.ndim != 2 for t in takes) or n < 2:
    raise ValueError(f"principal_axes: need [N >= 2, D] frames, got {[t.shape for t in takes]}")
  variance, axes = np.linalg.eigh(_covariance(takes, n))
  axes = axes[:, np.argsort(variance)[::-1]]
  signs = np.sign(axes[np.abs(axes).argmax(0), np.arange(axes.shape[1])])
  return (axes * np.where(signs == 0, 1.0, signs)).astype(np.float32)


def _covariance(takes: list[np.ndarray], n: int) -> np.ndarray:
  """The frames' ``[D, D]`` covariance (ddof 1) in float64: ``np.cov`` when a float64 copy of them is small,
  else in two passes over the takes (their mean, then the centred products), one take in float64 at a time."""
  if n * takes[0].shape[1] <= COVARIANCE_IN_ONE:
    return np.cov(np.concatenate(takes).astype(np.float64), rowvar=False)
  d = takes[0].shape[1]
  mean = np.zeros(d)
  for t in takes:
    mean += t.sum(0, dtype=np.float64)
  mean /= n
  products = np.zeros((d, d))
  for t in takes:
    c = t.astype(np.float64) - mean
    products += c.T @ c
  return products / (n - 1)


def feature_dim(skeleton: Skeleton, representation: str) -> int:
  """Features per frame of ``representation`` for ``skeleton``."""
  j = skeleton.num_joints
  if representation == "canonical":
    return 4 + 3 * (j - 1) + 3 * j + len(skeleton.feet)
  if representation == "directions":
    return 3 + 3 * j
  return 3 * j


def hips(skeleton: Skeleton) -> tuple[int, int]:
  """``(left, right)``: the root's children that are each other's twins, the left one by name."""
  kids = [c for p, c in skeleton.bones if p == skeleton.root]
  pairs = [(a, skeleton.twins[a]) for a in kids if skeleton.twins[a] != a and skeleton.twins[a] in kids]

  for a, b in pairs:
    if split_name(skeleton.joint_names[a])[0] == "left":
      return a, b
  raise UserError(
    f"skeleton {skeleton.name}: no left/right hip pair under the root (the canonical and directions "
    "representations need one to find the heading); use data.representation = 'bone_relative'"
  )


def leg_length(pos_TxJx3, skeleton: Skeleton) -> float:
  """Mean length of the chain from the first foot up to the root."""
  lengths = {j: float(v) for j, v in mean_bone_lengths(pos_TxJx3, skeleton).items()}  # summed in float64
  return float(chain_length(lengths, skeleton, skeleton.feet[0]))


def _represent(pos, skeleton: Skeleton, representation: str):
  if representation == "canonical":
    left, right = hips(skeleton)
    return transforms.to_canonical(
      jnp.asarray(pos), skeleton.root, left, right, tuple(skeleton.feet), leg_length(pos, skeleton)
    )
  if representation == "directions":
    return transforms.to_directions(jnp.asarray(pos), tuple(skeleton.parents))
  if representation == "absolute":
    return jnp.asarray(pos)
  if representation == "bone_relative":
    return transforms.to_bone_relative(pos, skeleton.parents)
  if representation == "root_relative":
    return transforms.to_root_relative(pos, skeleton.root)
  raise ValueError(f"unknown representation {representation!r}; one of {REPRESENTATIONS}")


# Decoding as two compiled programs (one per shape) instead of some forty operations run one by one, each compiled
# anew for every sample length: most of what a short `chorjax sample` or a calibration spent compiling.
_STATIC = ("representation", "skeleton", "up_axis")


SINK = 0.015  # decode(ground=True): no foot further below the training floor than this share of the leg


@functools.partial(jax.jit, static_argnames=(*_STATIC, "rigid", "ground", "finish"))
def _decoded(
  z, mean, std, place, lengths, floor, inv_scale, max_rise, *, representation, skeleton, up_axis, rigid, ground, finish
):
  """:meth:`Features.decode` up to ``lock_feet``: y-up scaled positions, or (``finish``) data-space ones."""
  rep = transforms.denormalize(z, mean, std)
  pos = _unrepresent(rep, representation, skeleton, lengths, place)
  if rigid:
    pos = transforms.rigid_bones(pos, skeleton.parents, lengths)
  if ground:
    contacts = rep[..., -len(skeleton.feet) :]  # canonical features end with the feet's contacts
    sink = None if lengths is None else SINK * chain_length(lengths, skeleton, skeleton.feet[0])
    pos = transforms.ground_feet(pos, contacts, skeleton.feet, floor, root=skeleton.root, max_rise=max_rise, sink=sink)
  return _uncanonical(pos, up_axis, inv_scale) if finish else pos


@functools.partial(jax.jit, static_argnames=_STATIC)
def _locked(pos, z, mean, std, max_step, inv_scale, *, representation, skeleton, up_axis):
  """:meth:`Features.decode`'s ``lock_feet`` on y-up scaled positions, then back to data space."""
  contacts = transforms.denormalize(z, mean, std)[..., -len(skeleton.feet) :]
  pos = transforms.lock_feet(pos, contacts, skeleton.feet, max_step=max_step)
  return _uncanonical(pos, up_axis, inv_scale)


def _uncanonical(pos, up_axis: str, inv_scale):
  return transforms.rotate(transforms.scale_units(pos, inv_scale), transforms.up_axis_matrix(up_axis).T)


def _unrepresent(rep, representation: str, skeleton: Skeleton, lengths, place=None):
  if representation == "canonical":
    return transforms.from_canonical(rep, skeleton.root, skeleton.num_joints, place)
  if representation == "directions":
    start = (0.0, 0.0) if place is None else jnp.asarray(place)[..., 1:3]
    return transforms.from_directions(rep, skeleton.parents, lengths, start)
  rep = rep.reshape(rep.shape[:-1] + (skeleton.num_joints, 3))
  if representation == "absolute":
    return rep
  if representation == "bone_relative":
    return transforms.from_bone_relative(rep, skeleton.parents)
  if representation == "root_relative":
    return transforms.from_root_relative(rep, skeleton.root)
  raise ValueError(f"unknown representation {representation!r}; one of {REPRESENTATIONS}")
