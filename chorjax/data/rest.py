"""Rest frames and jumps: where a take's pose or root jumps far beyond its own frame-to-frame steps.

A step (the largest joint move between two frames, the pose measured from the root, or the root's own
move) over ``JUMP`` times the take's 99th-percentile step and over 5% of the body's size is a jump: real
motion, however fast, stays within about twice that step, and a converter's rest pose (arms out) in frame 0
jumps far beyond it (the figures: ``docs/perf-notes.md``). A frame jumped into and out of is a rest/T-pose
(or glitch) frame; a run of jumps at the start is a **leading rest pose** (the rest frame and the blend out of
it), which training and ``data convert`` drop by default (``drop_leading_rest``; ``chorjax data check`` reports all).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from chorjax.data.motion import Motion

JUMP = 3.0  # a step over JUMP x the take's 99th-percentile step is a jump (see the module docstring)
LEAD_SECONDS = 0.1  # a leading rest pose: frame 0 and at most this long a blend out of it


@dataclasses.dataclass(frozen=True)
class Jumps:
  """Where a take's pose or root jumps far beyond its own frame-to-frame steps (``find_jumps``).

  Attributes:
    leading: frames at the start that are a rest pose and the blend out of it (0: none).
    pose: frames (numbered from 0) the pose jumps into, after the leading ones.
    root: frames the root jumps into, after the leading ones.
    rest: frames the pose jumps into and out of (rest or T-pose frames inside the take).
    worst: the largest step after the leading frames / the take's 99th-percentile step.
    lead_ratio: frame 0's step / the take's 99th-percentile step (0 without a leading rest pose).
  """

  leading: int = 0
  pose: tuple = ()
  root: tuple = ()
  rest: tuple = ()
  worst: float = 0.0
  lead_ratio: float = 0.0

  def describe(self) -> list[str]:
    """One note per finding, with frame numbers."""
    out = []
    if self.leading:
      blend = f" and the {self.leading - 1} frame(s) blending out of it" if self.leading > 1 else ""
      out.append(
        f"frame 0 is a rest pose ({self.lead_ratio:.0f}x the take's 99th-percentile step){blend}: "
        f"training and `data convert` drop {'frame 0' if self.leading == 1 else f'frames 0-{self.leading - 1}'} "
        "(data.keep_rest_frames keeps them)"
      )
    if self.rest:
      out.append(f"the pose jumps away and back at frame(s) {_frames(self.rest)} (rest/T-pose or glitch frames)")
    other = [f for f in self.pose if f not in self.rest and f - 1 not in self.rest]
    if other:
      out.append(f"the pose jumps at frame(s) {_frames(other)} (up to {self.worst:.1f}x the 99th-percentile step)")
    if self.root:
      out.append(f"the root jumps at frame(s) {_frames(self.root)}")
    return out


def _frames(frames) -> str:
  shown = ", ".join(str(f) for f in frames[:8])
  return shown + (f" and {len(frames) - 8} more" if len(frames) > 8 else "")


def _steps(positions, root: int | None) -> tuple[np.ndarray, np.ndarray, float]:
  """(pose step [T-1], root step [T-1], body size): the largest joint move measured from the root
  (a marker set: from the markers' centroid), the root's move, and the median per-frame spread."""
  p = np.asarray(positions, np.float64)
  anchor = p.mean(1, keepdims=True) if root is None else p[:, root : root + 1]
  pose = np.linalg.norm(np.diff(p - anchor, axis=0), axis=-1).max(-1)
  moved = np.linalg.norm(np.diff(anchor[:, 0], axis=0), axis=-1)
  body = float(np.median(np.ptp(p, axis=1).max(-1)))
  return pose, moved, body


def _jumps_in(step: np.ndarray, body: float, p99: float) -> np.ndarray:
  return (step > JUMP * p99) & (step > 0.05 * body)


def find_jumps(motion: Motion) -> Jumps:
  """Rest frames, pose jumps and root jumps of ``motion`` (see the module docstring)."""
  if motion.num_frames < 3:
    return Jumps()
  root = motion.skeleton.root if motion.skeleton.bones else None
  pose, moved, body = _steps(motion.positions, root)
  p99 = np.percentile(pose, 99)
  pose_jump, root_jump = _jumps_in(pose, body, p99), _jumps_in(moved, body, np.percentile(moved, 99))
  lead = 0
  if pose_jump[0]:
    cap = max(round(LEAD_SECONDS * motion.fps), 1)
    usual = np.percentile(pose[cap:], 99) if len(pose) > 2 * cap else p99
    lead = 1  # the blend out of the rest pose: steps over 2x the usual ones (real motion stays within ~2x)
    while lead < min(cap, len(pose)) and pose[lead] > 2 * usual:
      lead += 1
  jumps = np.flatnonzero(pose_jump[lead:]) + lead
  rest = tuple(int(t) for t in jumps if t + 1 in jumps)
  return Jumps(
    leading=lead,
    pose=tuple(int(t) + 1 for t in jumps),
    root=tuple(int(t) + 1 for t in np.flatnonzero(root_jump[lead:]) + lead),
    rest=tuple(t + 1 for t in rest),
    worst=float(pose[lead:].max() / max(p99, 1e-12)),
    lead_ratio=float(pose[0] / max(p99, 1e-12)) if lead else 0.0,
  )


def drop_leading_rest(motion: Motion) -> tuple[Motion, int]:
  """``motion`` without its leading rest pose (``Jumps.leading`` frames), and how many were dropped."""
  lead = find_jumps(motion).leading
  if not lead:
    return motion, 0
  return motion.replace(positions=motion.positions[lead:]), lead


def drop_leading_rests(motions, keep_flag: str = "data.keep_rest_frames = true") -> tuple[list[Motion], str | None]:
  """Every take without its leading rest pose, and one line for the user saying which lost one (None if
  none did; ``keep_flag`` names the setting that keeps them: training's key, or ``data convert``'s flag)."""
  kept = [drop_leading_rest(m) for m in motions]
  dropped = {m.name: n for m, n in kept if n}
  if not dropped:
    return [m for m, _ in kept], None
  names = sorted(dropped)
  takes = names[0] if len(names) == 1 else f"{len(names)} takes ({names[0]}, ...)"
  counts = sorted(set(dropped.values()))
  n = f"{counts[0]}" if len(counts) == 1 else f"{counts[0]}-{counts[-1]}"
  return [m for m, _ in kept], f"dropped a leading rest pose ({n} frames) of {takes}; {keep_flag} keeps it"
