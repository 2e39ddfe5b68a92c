"""``chorjax live``'s stream onto an armature: a thread receives the frames, Blender's timer poses the newest.

The thread only reads the WebSocket (the ``websockets`` package; the add-on carries a copy under ``vendor/``
for a Blender without it) and keeps the newest frame; ``Receiver.poll``, run by ``bpy.app.timers`` on
Blender's main thread, poses the armature with it, so Blender's data is only touched where Blender allows.
"""

from __future__ import annotations

import json
import sys
import threading
from pathlib import Path

import numpy as np

from .rig import FEET, Rig, on_floor, to_blender


def _connect():
  try:
    from websockets.sync.client import connect
  except ImportError:
    sys.path.append(str(Path(__file__).with_name("vendor")))
    from websockets.sync.client import connect
  return connect


class Receiver:
  """Frames of a running ``chorjax live`` (``url``: its ``ws://HOST:PORT/ws``) for one armature.

  Attributes:
    received: frames received so far; ``shown``: frames posed so far; ``error``: why the stream ended, or
    None; ``hello``: the server's first message (fps, joint names, up axis, motions); ``last``: the
    frame posed last (Blender's axes).
  """

  def __init__(self, armature_object, url: str):
    self.rig, self.url = Rig(armature_object), url
    self.received = self.shown = 0
    self.hello, self.error, self.latest, self.last, self.scale = None, None, None, None, None
    self.floor: float | None = None
    self.lock, self.stopping, self.socket = threading.Lock(), False, None
    self.thread = threading.Thread(target=self._listen, name="chorjax live", daemon=True)
    self.thread.start()

  def _listen(self) -> None:
    try:
      with _connect()(self.url, open_timeout=10, max_size=2**24, proxy=None) as socket:
        self.socket = socket
        for message in socket:
          data = json.loads(message)
          if "hello" in data:
            self.hello = data["hello"]
          elif "frame" in data and self.hello is not None:
            frame = to_blender(np.asarray(data["positions"], np.float64), self.hello["up_axis"])
            if self.floor is None:  # the run's training floor, else where the first frame's lower foot is
              self.floor = self.hello.get("floor")
              self.floor = float(frame[FEET, 2].min()) if self.floor is None else self.floor
            frame = on_floor(frame[None], self.floor)[0]
            with self.lock:
              self.latest, self.received = frame, self.received + 1
    except Exception as e:  # the stream's end, for any reason, is shown in the panel
      if not self.stopping:
        self.error = f"{type(e).__name__}: {e}"
    self.error = self.error or "the stream ended"

  def poll(self) -> float | None:
    """Poses the armature with the newest frame; the seconds until the next call (None: the stream ended)."""
    with self.lock:
      frame, self.latest = self.latest, None
    if frame is not None:
      if self.scale is None:
        self.scale = self.rig.scale(frame[None])
      self.rig.apply(self.rig.pose(self.rig.joints(frame, self.scale)))
      self.shown, self.last = self.shown + 1, frame
    if self.error is not None and self.latest is None:
      return None
    return 0.5 / float(self.hello["fps"]) if self.hello else 0.05

  def stop(self) -> None:
    self.stopping = True
    if self.socket is not None:
      self.socket.close()
    self.thread.join(timeout=5)
