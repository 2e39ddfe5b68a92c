"""Run by Blender's Python (the bpy package): imports a glTF with Blender's own importer at FPS frames per
second and prints, as one JSON line after "POSITIONS", the world position of each named node at every frame
from 0 to FRAMES - 1 (Blender's z-up axes).

    python blender_positions.py FILE.glb FPS FRAMES '["joint", ...]'
"""

import json
import sys

import bpy

path, fps, frames, names = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), json.loads(sys.argv[4])
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
scene.render.fps = fps
bpy.ops.import_scene.gltf(filepath=path)
positions = []
for frame in range(frames):
  scene.frame_set(frame)
  positions.append([list(bpy.data.objects[name].matrix_world.translation) for name in names])
print("POSITIONS" + json.dumps(positions))
