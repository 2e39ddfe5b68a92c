"""What a joint's name says: its side and its part, for any rig's naming (Mixamo, HumanIK, Rigify, CMU, ...).

Standard library only: the Blender add-on (``chorjax blender-addon``) ships this module as it is, to find the
parts of an armature by the same rules ``chorjax.data.mapping`` reads a take's joints with.
"""

from __future__ import annotations

import re

# Synonyms per limb joint, in order of preference (``Ankle`` before ``Foot``: where both exist, the
# foot is the toe; ``Wrist`` before ``Hand``; ``UpperArm``/``Arm`` before ``Shoulder``: where both exist,
# the shoulder is the clavicle).
SYNONYMS = {
  "ankle": ("ankle", "foot"),
  "knee": ("knee", "leg", "lowerleg", "shin", "calf", "lowleg"),
  "hip": ("upleg", "upperleg", "thigh", "hip", "upperthigh"),
  "wrist": ("wrist", "hand"),
  "elbow": ("elbow", "forearm", "lowerarm"),
  "shoulder": ("upperarm", "arm", "shoulder", "uparm"),
}
_KNOWN_BASES = {b for v in SYNONYMS.values() for b in v} | {"collar", "clavicle", "toe", "toebase", "foot", "eye"}
_SIDES = {"left": "left", "right": "right", "l": "left", "r": "right"}


def split_name(name: str) -> tuple[str | None, str, bool]:
  """``(side, base, is_end)`` of a joint name: ``mixamorig:LeftUpLeg`` -> ``("left", "upleg", False)``.

  The base is lower case without separators; ``_end`` (End Sites, see ``bvh.read_bvh``) sets is_end.
  """
  raw = re.split(r"[:|]", name)[-1]
  is_end = bool(re.search(r"[_ .-]?end$", raw, re.I)) and len(raw) > 4
  if is_end:
    raw = re.sub(r"[_ .-]?end$", "", raw, flags=re.I)
  camel = re.sub(r"([A-Z])([A-Z][a-z])", r"\1_\2", re.sub(r"([a-z0-9])([A-Z])", r"\1_\2", raw))
  low = [w.lower() for w in re.split(r"[_ .\-]+", camel) if w]
  low = [w for k, w in enumerate(low) if not (k == 0 and len(low) > 1 and re.fullmatch(r"bip\d*|def|jnt|bn", w))]
  side = None
  at = next((k for k, w in enumerate(low) if w in _SIDES), None) if len(low) > 1 else None
  if at is not None:
    side, low = _SIDES[low[at]], low[:at] + low[at + 1 :]
  base = "".join(low)
  if side is None and len(base) > 1 and base[0] in "lr" and base[1:] in _KNOWN_BASES:  # lhand, rfoot
    side, base = _SIDES[base[0]], base[1:]
  return side, base, is_end
