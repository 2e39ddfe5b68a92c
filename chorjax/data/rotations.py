"""Rotation helpers (NumPy, float64): Euler angles in any axis order, and minimal/best-fit rotations."""

from __future__ import annotations

import numpy as np


def axis_rotation(axis: str, angle_rad) -> np.ndarray:
  """``[..., 3, 3]`` rotation matrices about x, y or z (right-handed)."""
  c, s = np.cos(angle_rad), np.sin(angle_rad)
  o, z = np.ones_like(c), np.zeros_like(c)
  m = {
    "x": [[o, z, z], [z, c, -s], [z, s, c]],
    "y": [[c, z, s], [z, o, z], [-s, z, c]],
    "z": [[c, -s, z], [s, c, z], [z, z, o]],
  }[axis.lower()]
  return np.moveaxis(np.array(m, dtype=np.float64), (0, 1), (-2, -1))


def euler_to_matrix(angles_deg_Nx3, order: str) -> np.ndarray:
  """Intrinsic rotations in the listed order: ``order='zyx'`` gives Rz @ Ry @ Rx (BVH convention)."""
  a = np.deg2rad(np.asarray(angles_deg_Nx3, np.float64))
  m = np.broadcast_to(np.eye(3), a.shape[:-1] + (3, 3)).copy()
  for k, ax in enumerate(order.lower()):
    m = m @ axis_rotation(ax, a[..., k])
  return m


def matrix_to_euler(m_Nx3x3, order: str) -> np.ndarray:
  """Inverse of ``euler_to_matrix`` for any of the six Tait-Bryan orders, in degrees."""
  order = order.lower()
  i, j, k = ("xyz".index(c) for c in order)
  sign = 1.0 if (j - i) % 3 == 1 else -1.0  # even permutation of xyz
  m = np.asarray(m_Nx3x3, np.float64)
  # R = Ri(a) Rj(b) Rk(c): R[i,k] = sign * sin(b)
  b = np.arcsin(np.clip(sign * m[..., i, k], -1.0, 1.0))
  a = np.arctan2(-sign * m[..., j, k], m[..., k, k])
  c = np.arctan2(-sign * m[..., i, j], m[..., i, i])
  return np.rad2deg(np.stack([a, b, c], axis=-1))


def swing(u_Nx3, v_Nx3) -> np.ndarray:
  """The smallest rotation taking unit directions u to v (no twist about the bone)."""
  u = u_Nx3 / np.maximum(np.linalg.norm(u_Nx3, axis=-1, keepdims=True), 1e-12)
  v = v_Nx3 / np.maximum(np.linalg.norm(v_Nx3, axis=-1, keepdims=True), 1e-12)
  axis = np.cross(u, v)
  s, c = np.linalg.norm(axis, axis=-1), np.sum(u * v, axis=-1)
  k = axis / np.maximum(s, 1e-12)[..., None]
  kx = np.zeros(u.shape[:-1] + (3, 3))
  kx[..., 0, 1], kx[..., 0, 2], kx[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
  kx[..., 1, 0], kx[..., 2, 0], kx[..., 2, 1] = k[..., 2], -k[..., 1], k[..., 0]
  eye = np.broadcast_to(np.eye(3), kx.shape)
  r = eye + s[..., None, None] * kx + (1 - c)[..., None, None] * (kx @ kx)
  # opposite directions: turn 180 degrees about any axis perpendicular to u
  opposite = (s < 1e-9) & (c < 0)
  if np.any(opposite):
    perp = np.cross(u[opposite], np.eye(3)[np.argmin(np.abs(u[opposite]), axis=-1)])
    perp /= np.linalg.norm(perp, axis=-1, keepdims=True)
    r[opposite] = 2 * perp[..., :, None] * perp[..., None, :] - np.eye(3)
  return r


def best_fit_rotation(rest_NxKx3, obs_NxKx3) -> np.ndarray:
  """Kabsch: the rotation R (per row) minimizing sum ||R rest_k - obs_k||^2 over K directions."""
  h = np.swapaxes(rest_NxKx3, -1, -2) @ obs_NxKx3  # [N, 3, 3] = sum rest^T obs
  u, _, vt = np.linalg.svd(h)
  d = np.sign(np.linalg.det(np.swapaxes(vt, -1, -2) @ np.swapaxes(u, -1, -2)))
  fix = np.broadcast_to(np.eye(3), h.shape).copy()
  fix[..., 2, 2] = d
  return np.swapaxes(vt, -1, -2) @ fix @ np.swapaxes(u, -1, -2)


def matrix_to_quaternion(m_Nx3x3) -> np.ndarray:
  """Unit quaternions ``[..., 4]`` as ``(x, y, z, w)`` (glTF's order) of rotation matrices, ``w >= 0``."""
  m = np.asarray(m_Nx3x3, np.float64)
  trace = m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2]
  # each of the four candidates is computed from its largest term (Shepperd): stable for every rotation
  cands = np.stack(
    [
      np.stack([m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1], 1 + trace], -1),
      np.stack(
        [
          1 + 2 * m[..., 0, 0] - trace,
          m[..., 0, 1] + m[..., 1, 0],
          m[..., 0, 2] + m[..., 2, 0],
          m[..., 2, 1] - m[..., 1, 2],
        ],
        -1,
      ),
      np.stack(
        [
          m[..., 0, 1] + m[..., 1, 0],
          1 + 2 * m[..., 1, 1] - trace,
          m[..., 1, 2] + m[..., 2, 1],
          m[..., 0, 2] - m[..., 2, 0],
        ],
        -1,
      ),
      np.stack(
        [
          m[..., 0, 2] + m[..., 2, 0],
          m[..., 1, 2] + m[..., 2, 1],
          1 + 2 * m[..., 2, 2] - trace,
          m[..., 1, 0] - m[..., 0, 1],
        ],
        -1,
      ),
    ],
    -2,
  )
  best = np.argmax(np.stack([trace, m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]], -1), -1)
  q = np.take_along_axis(cands, best[..., None, None], axis=-2)[..., 0, :]
  q /= np.linalg.norm(q, axis=-1, keepdims=True)
  return np.where(q[..., 3:] < 0, -q, q)


def quaternion_to_matrix(q_Nx4) -> np.ndarray:
  """Rotation matrices ``[..., 3, 3]`` of unit quaternions ``(x, y, z, w)`` (the inverse of
  :func:`matrix_to_quaternion`)."""
  x, y, z, w = np.moveaxis(np.asarray(q_Nx4, np.float64), -1, 0)
  rows = [
    [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
    [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
    [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
  ]
  return np.stack([np.stack(row, -1) for row in rows], -2)


def pose_rotations(pos_TxJx3, parents, order) -> np.ndarray:
  """Every joint's global rotation ``[T, J, 3, 3]`` from the first frame (the rest pose) to each frame, by
  inverse kinematics of the positions: a joint with one child turns by the smallest rotation (swing) that
  takes its rest bone to the observed one, relative to its parent's frame (a bone never twists about
  itself); one with several children by the best-fit rotation of all their directions (Kabsch); a leaf
  turns with its parent. ``order``: the joints, parents first."""
  pos = np.asarray(pos_TxJx3, np.float64)
  t, j = pos.shape[:2]
  children = {k: [c for c in range(j) if parents[c] == k] for k in range(j)}
  rest = pos[0]
  glob = np.zeros((t, j, 3, 3))
  for k in order:
    parent = parents[k]
    parent_r = np.broadcast_to(np.eye(3), (t, 3, 3)) if parent < 0 else glob[:, parent]
    kids = children[k]
    if not kids:
      glob[:, k] = parent_r
    elif len(kids) == 1:
      rest_dir = np.einsum("tij,j->ti", parent_r, rest[kids[0]] - rest[k])
      glob[:, k] = swing(rest_dir, pos[:, kids[0]] - pos[:, k]) @ parent_r
    else:
      rest_dirs = np.stack([rest[c] - rest[k] for c in kids])
      obs = np.stack([pos[:, c] - pos[:, k] for c in kids], axis=1)
      glob[:, k] = best_fit_rotation(np.broadcast_to(rest_dirs, obs.shape), obs)
  return glob


def local_transforms(pos_TxJx3, parents, glob_TxJx3x3) -> tuple[np.ndarray, np.ndarray]:
  """``(translation [T, J, 3], rotation [T, J, 3, 3])`` of each joint in its parent's frame (the root's in
  the world's) that put every joint exactly at ``pos`` with the global rotations ``glob``."""
  pos = np.asarray(pos_TxJx3, np.float64)
  p = np.asarray(parents)
  has = p >= 0
  parent_r = np.where(has[None, :, None, None], glob_TxJx3x3[:, np.maximum(p, 0)], np.eye(3))
  parent_t = np.where(has[None, :, None], pos[:, np.maximum(p, 0)], 0.0)
  translation = np.einsum("tkji,tkj->tki", parent_r, pos - parent_t)
  rotation = np.swapaxes(parent_r, -1, -2) @ glob_TxJx3x3
  return translation, rotation
