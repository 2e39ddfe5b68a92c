"""``chorjax blender-addon``: the Blender add-on (``chorjax/blender_addon``) packed as a zip for Blender."""

from __future__ import annotations

import importlib.metadata
import importlib.util
import json
import zipfile
from pathlib import Path

import numpy as np

from chorjax.data.skeletons import MPII16
from chorjax.data.transforms import up_axis_matrix
from chorjax.errors import UP_AXES, UserError, atomic_write, check_output, refuse_existing

PACKAGE = Path(__file__).resolve().parents[1]  # chorjax/


def write_blender_addon(output, *, force: bool = False) -> Path:
  """``chorjax blender-addon``: the Blender add-on as a zip to install in Blender (Preferences > Add-ons >
  Install from Disk): ``chorjax/blender_addon`` with the joint-name rules (``chorjax.data.joint_names``), the
  16-joint layout and the up axes it reads, and a copy of the ``websockets`` package (with its licence) for
  live mode. It runs on Blender's own Python; see its module docstring. Returns the zip's path."""
  out, _ = check_output(output, (".zip",))
  refuse_existing([out], force)
  spec = importlib.util.find_spec("websockets")
  if spec is None or not spec.submodule_search_locations:
    raise UserError("the add-on carries the websockets package for live mode: pip install 'chorjax[live]'")
  websockets = Path(next(iter(spec.submodule_search_locations)))
  licence = [f for f in importlib.metadata.files("websockets") or [] if f.name == "LICENSE"]
  shipped = {
    "version": importlib.metadata.version("chorjax"),
    "joints": list(MPII16.joint_names),
    "y_up": {axis: np.asarray(up_axis_matrix(axis)).tolist() for axis in UP_AXES},
  }

  def write(tmp):
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
      for f in sorted((PACKAGE / "blender_addon").glob("*.py")):
        z.write(f, f"chorjax_blender/{f.name}")
      z.write(PACKAGE / "data" / "joint_names.py", "chorjax_blender/joint_names.py")
      z.writestr("chorjax_blender/chorjax.json", json.dumps(shipped, indent=1))
      for f in sorted(websockets.rglob("*.py")):
        z.write(f, f"chorjax_blender/vendor/websockets/{f.relative_to(websockets).as_posix()}")
      for f in licence[:1]:
        z.write(Path(str(f.locate())), "chorjax_blender/vendor/websockets.LICENSE")

  return atomic_write(out, write, overwrite=True)
