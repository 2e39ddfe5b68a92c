"""chorjax for Blender: a chorjax dance onto the selected armature, from a file or live.

Written into a zip by ``chorjax blender-addon -o chorjax_blender.zip``; install it in Blender (Edit >
Preferences > Add-ons > Install from Disk). Then, with a humanoid armature selected:

- File > Import > chorjax dance (.npz, .csv), or the sidebar's chorjax tab: a sample (``chorjax sample
  -o dance.npz``) becomes a new action on the armature, one key a frame, at the dance's frame rate;
- the sidebar's "Live" button: receives a running ``chorjax live RUN`` (its ``ws://HOST:PORT/ws``) and poses
  the armature with every frame as it arrives, until "Stop".

Runs on Blender's own Python (numpy, mathutils); nothing of chorjax needs to be installed there.
"""

from __future__ import annotations

bl_info = {
  "name": "chorjax",
  "author": "chorjax",
  "version": (1, 0, 0),
  "blender": (4, 2, 0),
  "location": "File > Import > chorjax dance; 3D Viewport > Sidebar > chorjax",
  "description": "A chorjax dance onto the selected armature: import a sample, or receive chorjax live",
  "category": "Animation",
}

import bpy  # noqa: E402
from bpy_extras.io_utils import ImportHelper  # noqa: E402

from .receiver import Receiver  # noqa: E402
from .rig import DanceError, Rig, read_dance  # noqa: E402

RECEIVERS: dict = {}  # armature object name -> its live Receiver


def _armature(context):
  obj = context.active_object
  if obj is None or obj.type != "ARMATURE":
    raise DanceError("select an armature first")
  return obj


class CHORJAX_OT_import_dance(bpy.types.Operator, ImportHelper):
  """Import a chorjax dance (.npz, or .csv of the 16-joint layout) onto the selected armature as a new action"""

  bl_idname = "chorjax.import_dance"
  bl_label = "Import chorjax dance"
  bl_options = {"REGISTER", "UNDO"}
  filter_glob: bpy.props.StringProperty(default="*.npz;*.csv", options={"HIDDEN"})  # type: ignore[valid-type]
  dancer: bpy.props.IntProperty(name="Dancer", description="which of an .npz's dancers", default=0, min=0)  # type: ignore[valid-type]
  fps: bpy.props.FloatProperty(name="CSV frame rate", default=30.0, min=0.001)  # type: ignore[valid-type]
  up_axis: bpy.props.EnumProperty(  # type: ignore[valid-type]
    name="CSV up axis",
    items=[(a, a, f"the file's {a} points up") for a in ("-y", "y", "z", "-z", "x", "-x")],
    default="-y",
  )

  def execute(self, context):
    try:
      obj = _armature(context)
      positions, fps = read_dance(self.filepath, self.fps, self.up_axis, self.dancer)
      scene = context.scene
      frames = Rig(obj).keyframe(positions, scene.frame_start, bpy.path.display_name_from_filepath(self.filepath))
    except DanceError as e:
      self.report({"ERROR"}, str(e))
      return {"CANCELLED"}
    scene.render.fps, scene.render.fps_base = max(round(fps), 1), max(round(fps), 1) / fps
    scene.frame_end = scene.frame_start + frames - 1
    self.report({"INFO"}, f"{frames} frames at {fps:g} fps onto {obj.name}")
    return {"FINISHED"}


class CHORJAX_OT_live(bpy.types.Operator):
  """Pose the selected armature with a running chorjax live stream, frame by frame"""

  bl_idname = "chorjax.live"
  bl_label = "Live"
  url: bpy.props.StringProperty(name="URL", default="ws://127.0.0.1:8765/ws")  # type: ignore[valid-type]

  def execute(self, context):
    try:
      obj = _armature(context)
      stop_live(obj.name)
      receiver = RECEIVERS[obj.name] = Receiver(obj, self.url)
    except DanceError as e:
      self.report({"ERROR"}, str(e))
      return {"CANCELLED"}
    bpy.app.timers.register(receiver.poll)
    self.report({"INFO"}, f"{obj.name} follows {self.url}")
    return {"FINISHED"}


class CHORJAX_OT_live_stop(bpy.types.Operator):
  """Stop following chorjax live"""

  bl_idname = "chorjax.live_stop"
  bl_label = "Stop"

  def execute(self, context):
    for name in list(RECEIVERS):
      stop_live(name)
    return {"FINISHED"}


def stop_live(name: str) -> None:
  receiver = RECEIVERS.pop(name, None)
  if receiver is not None:
    if bpy.app.timers.is_registered(receiver.poll):
      bpy.app.timers.unregister(receiver.poll)
    receiver.stop()


class CHORJAX_PT_panel(bpy.types.Panel):
  bl_label = "chorjax"
  bl_space_type = "VIEW_3D"
  bl_region_type = "UI"
  bl_category = "chorjax"

  def draw(self, context):
    layout = self.layout
    layout.operator(CHORJAX_OT_import_dance.bl_idname, text="Import dance")
    obj = context.active_object
    receiver = RECEIVERS.get(obj.name) if obj is not None else None
    if receiver is None:
      layout.prop(context.window_manager, "chorjax_live_url")
      layout.operator(CHORJAX_OT_live.bl_idname).url = context.window_manager.chorjax_live_url
    else:
      layout.label(text=receiver.error or f"{receiver.shown} frames shown")
      layout.operator(CHORJAX_OT_live_stop.bl_idname)


def _menu(self, context):
  self.layout.operator(CHORJAX_OT_import_dance.bl_idname, text="chorjax dance (.npz, .csv)")


CLASSES = (CHORJAX_OT_import_dance, CHORJAX_OT_live, CHORJAX_OT_live_stop, CHORJAX_PT_panel)


def register():
  for cls in CLASSES:
    bpy.utils.register_class(cls)
  bpy.types.WindowManager.chorjax_live_url = bpy.props.StringProperty(
    name="URL", default="ws://127.0.0.1:8765/ws", description="chorjax live's WebSocket"
  )
  bpy.types.TOPBAR_MT_file_import.append(_menu)


def unregister():
  for name in list(RECEIVERS):
    stop_live(name)
  bpy.types.TOPBAR_MT_file_import.remove(_menu)
  del bpy.types.WindowManager.chorjax_live_url
  for cls in reversed(CLASSES):
    bpy.utils.unregister_class(cls)
