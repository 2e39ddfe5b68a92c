"""The ``[patch]`` keys: the patch family's settings, registered with it (``Family.section``)."""

from __future__ import annotations

import dataclasses

from chorjax.fields import config_field as _field


@dataclasses.dataclass(frozen=True)
class PatchConfig:
  """Multi-scale nearest-patch synthesis from the training takes (``model.family = "patch"``): no network."""

  size: int = _field(
    5,
    "frames per patch: the pieces a dance is made of, matched and blended",
    more=(
      "Overlapping patches are averaged, which flattens motion where they disagree: a 2,000-frame dance from "
      "cmu94's 94_03 (820 frames, 30 fps) moved at 0.92x its speed with 5 (jitter 1.0x) and 0.62x with 11 "
      "(jitter 0.56x)."
    ),
    minimum=2,
  )
  coarsest: float = _field(
    0.2,
    "the coarsest scale's length as a share of the finest: synthesis starts there and refines scale by scale",
    more="The coarser the start, the longer the stretches recombined from the takes (and the less copied whole).",
    minimum=0.01,
    below=1.0,
  )
  factor: float = _field(0.75, "each scale's length over the next finer one's", minimum=0.1, below=1.0)
  iterations: int = _field(5, "matching and blending passes at each scale", minimum=1)
  alpha: float = _field(
    0.01,
    "completeness: a patch's distance divided by (alpha + its nearest distance to the dance so far)",
    more=(
      "Small values push the dance to use every patch of the takes (coverage) rather than the few that match "
      "best; large ones leave plain nearest-patch matching."
    ),
    minimum=0.0,
  )
  max_frames: int = _field(
    7200, "the most training frames the run keeps (4 minutes at 30 fps): the takes it recombines", minimum=2
  )
