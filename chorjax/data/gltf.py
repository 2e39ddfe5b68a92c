"""Binary glTF (``.glb``) out: the skeleton as a node hierarchy and the dance as its animation, for Blender,
three.js, Unity, Unreal and every tool that reads glTF 2.0.

Each joint is a node at its rest offset from its parent (the first frame is the rest pose). The animation
turns and moves every node each frame: its rotation is the one the BVH writer finds by inverse kinematics
(``rotations.pose_rotations``: a bone swings without twisting about itself), and its translation is its
real offset in its parent's frame that frame, so the joints land exactly where the positions put them
(bones stretch as much as the positions' do). glTF is y-up in metres: the positions are turned from the
motion's up axis and scaled from its units where they are known (``m``, ``cm``, ``mm``, ``in``); otherwise
the numbers are kept, and the asset's ``extras`` say so. Written with pygltflib (the ``export`` extra).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from chorjax.data.motion import Motion, topological_order
from chorjax.data.rotations import local_transforms, matrix_to_quaternion, pose_rotations, quaternion_to_matrix
from chorjax.data.transforms import to_y_up
from chorjax.errors import UserError, atomic_write

# metres per unit of the units a Motion may name (others are written as they are)
METRES = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254}


def gltf_positions(motion: Motion) -> tuple[np.ndarray, float]:
  """``(positions [T, J, 3] y-up in metres where the units are known, the factor applied)``: what the glTF
  holds of ``motion``."""
  scale = METRES.get(motion.units, 1.0)
  return np.asarray(to_y_up(np.asarray(motion.positions, np.float64), motion.up_axis), np.float64) * scale, scale


def _pygltflib(path, doing: str):
  """The pygltflib package, or a UserError naming the export extra."""
  try:
    import pygltflib  # the export extra: chorjax runs without it
  except ImportError:
    raise UserError(f"{path}: {doing} glTF needs pygltflib: pip install 'chorjax[export]'") from None
  return pygltflib


def write_glb(motion: Motion, path, *, overwrite: bool = True) -> Path:
  """Writes ``motion`` as a binary glTF at ``path`` (see the module docstring). Returns the path."""
  gl = _pygltflib(path, "writing")
  sk = motion.skeleton
  pos, scale = gltf_positions(motion)
  translation, rotation = local_transforms(pos, sk.parents, pose_rotations(pos, sk.parents, sk.topological_order))
  quaternion = matrix_to_quaternion(rotation)
  t, j = pos.shape[:2]
  times = (np.arange(t) / motion.fps).astype(np.float32)

  blob, views, accessors = bytearray(), [], []

  def add(array: np.ndarray, kind: str, bounds: bool = False) -> int:
    data = np.ascontiguousarray(array, np.float32)
    views.append(gl.BufferView(buffer=0, byteOffset=len(blob), byteLength=data.nbytes))
    blob.extend(data.tobytes())
    extra = {"min": data.reshape(len(data), -1).min(0).tolist(), "max": data.reshape(len(data), -1).max(0).tolist()}
    accessors.append(
      gl.Accessor(
        bufferView=len(views) - 1, componentType=gl.FLOAT, count=len(data), type=kind, **(extra if bounds else {})
      )
    )
    return len(accessors) - 1

  time_accessor = add(times, gl.SCALAR, bounds=True)
  children = [[c for c in range(j) if sk.parents[c] == k] for k in range(j)]
  nodes, samplers, channels = [], [], []
  for k in range(j):
    nodes.append(
      gl.Node(
        name=sk.joint_names[k],
        translation=translation[0, k].tolist(),
        rotation=quaternion[0, k].tolist(),
        children=children[k],
      )
    )
    for track, values, kind in (("translation", translation[:, k], gl.VEC3), ("rotation", quaternion[:, k], gl.VEC4)):
      samplers.append(gl.AnimationSampler(input=time_accessor, output=add(values, kind), interpolation="LINEAR"))
      target = gl.AnimationChannelTarget(node=k, path=track)
      channels.append(gl.AnimationChannel(sampler=len(samplers) - 1, target=target))
  extras = {"fps": motion.fps, "source_up_axis": motion.up_axis, "source_units": motion.units}
  extras["metres_per_unit"] = scale
  if motion.units not in METRES:
    extras["note"] = f"positions in the motion's own units ({motion.units}), not metres"
  doc = gl.GLTF2(
    asset=gl.Asset(version="2.0", generator="chorjax", extras=extras),
    scene=0,
    scenes=[gl.Scene(name=motion.name or "chorjax", nodes=[sk.root])],
    nodes=nodes,
    animations=[gl.Animation(name=motion.name or "dance", samplers=samplers, channels=channels)],
    accessors=accessors,
    bufferViews=views,
    buffers=[gl.Buffer(byteLength=len(blob))],
  )
  doc.set_binary_blob(bytes(blob))
  return atomic_write(path, lambda tmp: doc.save_binary(str(tmp)), overwrite=overwrite)


def read_glb_positions(path) -> np.ndarray:
  """The joint positions ``[T, J, 3]`` a ``.glb`` written by :func:`write_glb` animates (its nodes' local
  translations and rotations composed down the hierarchy, frame by frame): what an importer sees."""
  gl = _pygltflib(path, "reading")
  loaded = gl.GLTF2().load_binary(str(path))
  blob = None if loaded is None else loaded.binary_blob()
  if loaded is None or blob is None:
    raise UserError(f"{path}: not a binary glTF with its data chunk")
  doc: Any = loaded  # pygltflib types every field optional

  def values(index: int) -> np.ndarray:
    acc = doc.accessors[index]
    view = doc.bufferViews[acc.bufferView]
    width = {gl.SCALAR: 1, gl.VEC3: 3, gl.VEC4: 4}[acc.type]
    return np.frombuffer(blob, np.float32, acc.count * width, view.byteOffset or 0).reshape(acc.count, width)

  tracks = {}
  for channel in doc.animations[0].channels:
    tracks[(channel.target.node, channel.target.path)] = values(doc.animations[0].samplers[channel.sampler].output)
  j = len(doc.nodes)
  parent = [-1] * j
  for k, node in enumerate(doc.nodes):
    for c in node.children:
      parent[c] = k
  t = len(next(iter(tracks.values())))
  world_r, world_t = np.zeros((t, j, 3, 3)), np.zeros((t, j, 3))
  for k in topological_order(parent):
    r = quaternion_to_matrix(tracks[(k, "rotation")])
    local_t = tracks[(k, "translation")].astype(np.float64)
    if parent[k] < 0:
      world_r[:, k], world_t[:, k] = r, local_t
    else:
      world_r[:, k] = world_r[:, parent[k]] @ r
      world_t[:, k] = world_t[:, parent[k]] + np.einsum("tij,tj->ti", world_r[:, parent[k]], local_t)
  return world_t
