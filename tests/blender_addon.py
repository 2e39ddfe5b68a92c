"""Run by Blender's Python (the bpy package): installs the chorjax add-on from its zip, builds a Mixamo-like
armature (``mixamorig:`` names, y-up centimetres under an object turned and scaled as Blender's FBX importer
leaves a Mixamo character), imports a dance onto it and, given a live URL, follows ``chorjax live`` for
FRAMES frames. Prints one JSON line after "ADDON": the armature's rest joints and, per imported frame (and
for the last live frame), the world positions of the bone heads the dance drives.

    python blender_addon.py ADDON.zip DANCE.npz URL|- FRAMES
"""

import json
import math
import sys
import time

import bpy

zip_path, dance, url, frames = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.preferences.addon_install(filepath=zip_path)
bpy.ops.preferences.addon_enable(module="chorjax_blender")
import chorjax_blender  # noqa: E402  (installed just above)

# name: (parent, head, tail) in the armature's space: y up, +z forward, the character's left at +x, cm
BONES = {
  "Hips": (None, (0, 98, 0), (0, 108, 0)),
  "Spine": ("Hips", (0, 108, 0), (0, 120, 1)),
  "Spine1": ("Spine", (0, 120, 1), (0, 133, 1)),
  "Spine2": ("Spine1", (0, 133, 1), (0, 147, 0)),
  "Neck": ("Spine2", (0, 147, 0), (0, 157, 2)),
  "Head": ("Neck", (0, 157, 2), (0, 178, 2)),
  "HeadTop_End": ("Head", (0, 178, 2), (0, 186, 2)),
}
for side, x in (("Left", 1), ("Right", -1)):
  BONES |= {
    f"{side}Shoulder": ("Spine2", (x * 5, 143, 0), (x * 17, 144, -1)),
    f"{side}Arm": (f"{side}Shoulder", (x * 17, 144, -1), (x * 45, 144, -2)),
    f"{side}ForeArm": (f"{side}Arm", (x * 45, 144, -2), (x * 70, 144, 0)),
    f"{side}Hand": (f"{side}ForeArm", (x * 70, 144, 0), (x * 79, 144, 0)),
    f"{side}UpLeg": ("Hips", (x * 9, 94, 0), (x * 10, 51, 1)),
    f"{side}Leg": (f"{side}UpLeg", (x * 10, 51, 1), (x * 10, 9, -2)),
    f"{side}Foot": (f"{side}Leg", (x * 10, 9, -2), (x * 10, 2, 11)),
    f"{side}ToeBase": (f"{side}Foot", (x * 10, 2, 11), (x * 10, 2, 19)),
  }
armature = bpy.data.armatures.new("Armature")
rig = bpy.data.objects.new("Armature", armature)
bpy.context.scene.collection.objects.link(rig)
rig.rotation_euler, rig.scale = (math.pi / 2, 0, 0), (0.01, 0.01, 0.01)  # as an FBX from Mixamo imports
bpy.context.view_layer.objects.active = rig
bpy.ops.object.mode_set(mode="EDIT")
for name, (parent, head, tail) in BONES.items():
  bone = armature.edit_bones.new(f"mixamorig:{name}")
  bone.head, bone.tail = head, tail
  if parent is not None:
    bone.parent = armature.edit_bones[f"mixamorig:{parent}"]
    bone.use_connect = tuple(bone.parent.tail) == tuple(head)
bpy.ops.object.mode_set(mode="OBJECT")

DRIVEN = ["Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "RightUpLeg", "RightLeg", "RightFoot"]
DRIVEN += ["Neck", "Head", "LeftArm", "LeftForeArm", "LeftHand", "RightArm", "RightForeArm", "RightHand"]


def heads() -> list:
  """World positions of the driven bones' heads and of the head's tail (the top of the head)."""
  bpy.context.view_layer.update()
  pose = rig.pose.bones
  out = [list(rig.matrix_world @ pose[f"mixamorig:{n}"].head) for n in DRIVEN]
  return out + [list(rig.matrix_world @ pose["mixamorig:Head"].tail)]


def refusal(**kw) -> str:
  """The one line Blender reports when the import is refused."""
  try:
    bpy.ops.chorjax.import_dance(**kw)
  except RuntimeError as e:
    return str(e).strip()
  return "imported"


stick = bpy.data.objects.new("Stick", bpy.data.armatures.new("Stick"))
bpy.context.scene.collection.objects.link(stick)
bpy.context.view_layer.objects.active = stick
refused = {"not humanoid": refusal(filepath=dance), "not a dance": refusal(filepath=zip_path)}
bpy.context.view_layer.objects.active = rig
refused["no such dancer"] = refusal(filepath=dance, dancer=7)
rest = heads()
result = bpy.ops.chorjax.import_dance(filepath=dance)
scene = bpy.context.scene
report = {"import": sorted(result), "refused": refused, "rest": rest, "fps": scene.render.fps / scene.render.fps_base}
report["frame_range"] = [scene.frame_start, scene.frame_end]
report["imported"] = []
for f in range(scene.frame_start, scene.frame_end + 1):
  scene.frame_set(f)
  report["imported"].append(heads())
rig.animation_data.action = None  # live poses the armature itself
for bone in rig.pose.bones:
  bone.location, bone.rotation_quaternion = (0, 0, 0), (1, 0, 0, 0)

if url != "-":
  bpy.ops.chorjax.live(url=url)
  receiver = chorjax_blender.RECEIVERS[rig.name]
  until = time.monotonic() + 120
  while receiver.shown < frames and receiver.error is None and time.monotonic() < until:
    receiver.poll()
    time.sleep(0.002)
  report["live"] = {"received": receiver.received, "shown": receiver.shown, "error": receiver.error}
  report["live"]["frame"], report["live"]["heads"] = receiver.last.tolist(), heads()
  bpy.ops.chorjax.live_stop()
  report["live"]["stopped"] = not receiver.thread.is_alive()
print("ADDON" + json.dumps(report))
