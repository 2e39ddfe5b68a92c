"""``chorjax data check``: what a set of takes is, measured, before a single training step.

Per take: frames, rate, duration; the units and up axis the numbers themselves show (with the
evidence); the skeleton and its mapping onto the 16 training joints; bone-length stability;
non-finite values; held frames (gaps a reader filled, dropped frames); root teleports; the floor
under the feet over time. For the set: the config keys to use. Fatal problems (a file that cannot be
read, non-finite values, a skeleton that cannot be mapped) are returned one line each.

Detection, on the body rather than the headers:

- **up axis**: the signed axis along which the head stands above the feet (for a marker set: along
  which the middle 80% of the markers spread most in a frame, its sign the one that puts most markers
  in the upper half: a body carries more markers above the hips than below);
- **jumps**: a step (the largest joint move between two frames, the pose measured from the root, or the
  root's own move) over ``JUMP`` times the take's 99th-percentile step and over 5% of the body's size
  (:mod:`chorjax.data.rest`). A frame jumped into and out of is a rest/T-pose frame; a run of jumps
  at the start is a **leading rest pose** (the rest frame and the blend out of it), which training and
  ``data convert`` drop by default (``drop_leading_rest``);
- **units**: the mean leg (hip to knee to ankle; a marker set: standing height) against an adult's
  (0.85 m; 1.7 m), in the unit that brings it nearest: m, cm, mm, inches or CMU ASF units (1/0.0564444
  per metre). More than 1.5 times off in every unit: ``arbitrary``, with the metres per unit a body
  of usual size would have.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from chorjax.data.csv import has_sidecar
from chorjax.data.dataset import read_motions, resolve_files
from chorjax.data.mapping import HEAD_TOP_FROM_EYES, apply_mapping, find_mapping, leg_length, map_takes
from chorjax.data.motion import Motion, bone_length_cv
from chorjax.data.rest import drop_leading_rest, find_jumps  # noqa: F401  (drop_leading_rest: re-exported)
from chorjax.data.skeletons import MPII16
from chorjax.errors import UserError

LEG_M = 0.85  # hip -> knee -> ankle of an adult, metres
HEIGHT_M = 1.7  # a standing adult, metres (marker sets)
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "cmu_asf": 0.0564444}
AXES = ("y", "-y", "z", "-z", "x", "-x")


@dataclasses.dataclass
class TakeReport:
  """What ``check_take`` found in one take (``fatal`` lists what stops training)."""

  path: str
  frames: int = 0
  fps: float = 0.0
  joints: int = 0
  skeleton: str = ""
  mapping: str = ""
  up_axis: str = ""
  up_evidence: str = ""
  units: str = ""
  metres_per_unit: float = 0.0
  units_evidence: str = ""
  bone_cv: str = ""
  held_frames: int = 0
  teleports: int = 0
  floor: str = ""
  notes: list = dataclasses.field(default_factory=list)
  body: np.ndarray | None = None  # median 16-joint bone lengths (mapped takes), for comparing takes
  fatal: list = dataclasses.field(default_factory=list)

  @property
  def duration(self) -> float:
    return self.frames / self.fps if self.fps else 0.0


def _axis_vector(axis: str) -> np.ndarray:
  v = np.zeros(3)
  v["xyz".index(axis[-1])] = -1.0 if axis.startswith("-") else 1.0
  return v


def detect_up(motion: Motion, mapped: Motion | None) -> tuple[str, str]:
  """``(signed axis, evidence)``: where the head stands above the feet (a marker set: see the module)."""
  if mapped is not None:
    j = mapped.skeleton.joint_names.index
    feet = (mapped.positions[:, j("left_foot")] + mapped.positions[:, j("right_foot")]) / 2
    rise = mapped.positions[:, j("head_top")] - feet  # [T, 3]
    mean = rise.mean(0)
    k = int(np.argmax(np.abs(mean)))
    axis = ("-" if mean[k] < 0 else "") + "xyz"[k]
    share = float(np.mean(np.sign(rise[:, k]) == np.sign(mean[k])))
    others = np.delete(np.abs(mean), k).max()
    return (
      axis,
      f"head above feet along {axis} by {abs(mean[k]):.3g} (other axes <= {others:.3g}) in {share:.0%} of frames",
    )
  pos = motion.positions
  extent = np.median(np.percentile(pos, 90, axis=1) - np.percentile(pos, 10, axis=1), axis=0)  # per frame, robust
  k = int(np.argmax(extent))
  lo, hi = pos[..., k].min(1), pos[..., k].max(1)
  upper = float(np.mean((pos[..., k] - lo[:, None]) > (hi - lo)[:, None] / 2))
  axis = ("" if upper >= 0.5 else "-") + "xyz"[k]
  return axis, (
    f"markers spread most along {'xyz'[k]} (10-90% {extent[k]:.3g} vs {np.delete(extent, k).max():.3g}); "
    f"{max(upper, 1 - upper):.0%} of them in the half toward {axis}"
  )


def detect_units(motion: Motion, mapped: Motion | None, up_axis: str) -> tuple[str, float, str]:
  """``(unit, metres per unit, evidence)`` from the body's size (see the module docstring)."""
  if mapped is not None:
    size, want, what = leg_length(mapped.positions), LEG_M, "leg (hip-knee-ankle)"
  else:
    h = motion.positions @ _axis_vector(up_axis)
    size, want, what = float(np.median(h.max(1) - h.min(1))), HEIGHT_M, "height (marker spread)"
  off = {u: abs(np.log(size * f / want)) for u, f in UNITS.items()}
  unit = min(off, key=off.__getitem__)
  if off[unit] > np.log(1.5):
    per = want / size
    return "arbitrary", per, f"{what} {size:.4g} units: an adult's {want} m if 1 unit = {per:.3g} m"
  return unit, UNITS[unit], f"{what} {size:.4g} = {size * UNITS[unit]:.2f} m in {unit}"


def _floor(mapped: Motion | None, up_axis: str, fps: float) -> tuple[str, list[str]]:
  if mapped is None:
    return "-", []
  j = mapped.skeleton.joint_names.index
  up = _axis_vector(up_axis)
  feet = np.minimum(mapped.positions[:, j("left_foot")] @ up, mapped.positions[:, j("right_foot")] @ up)
  sec = max(round(fps), 1)
  floors = np.array([feet[k : k + sec].min() for k in range(0, len(feet), sec)])  # the lowest foot, each second
  scale = np.median(np.abs((mapped.positions[:, j("pelvis")] - mapped.positions[:, j("left_foot")]) @ up))
  drift = float(floors.max() - floors.min()) / (scale + 1e-9)
  text = f"{floors[0]:.3g} -> {floors[-1]:.3g} (range {np.ptp(floors):.3g} = {drift:.0%} of hip height)"
  notes = [f"the floor under the feet moves by {drift:.0%} of hip height over the take"] if drift > 0.15 else []
  return text, notes


def check_take(motion: Motion, joint_map=None, mapping=None) -> TakeReport:
  """Measures one take (see the module docstring); ``mapping``: the one its dataset uses (default: its own)."""
  r = TakeReport(motion.source or motion.name, motion.num_frames, motion.fps, motion.skeleton.num_joints)
  r.skeleton = motion.skeleton.name
  pos = motion.positions
  bad = int((~np.isfinite(pos)).any(axis=(1, 2)).sum())
  if bad:
    r.fatal.append(f"{r.path}: {bad} frames hold non-finite values (NaN/Inf)")
    return r
  if motion.num_frames < 2:
    r.fatal.append(f"{r.path}: {motion.num_frames} frame(s): nothing moves")
    return r
  if not np.ptp(pos, axis=(0, 1)).max() > 0:
    r.fatal.append(f"{r.path}: every joint of every frame at one point: no body to read")
    return r
  if not np.ptp(pos, axis=0).max() > 0:
    r.notes.append("does not move: every frame is the same pose (a frozen take teaches nothing)")
  mapped = None
  if motion.skeleton.bones:
    try:
      mapping = mapping or find_mapping(motion, joint_map)
      mapped = apply_mapping(motion, mapping)
      r.body = np.median(mapped.bone_lengths(), axis=0)
      r.mapping = f"{mapping.method}: " + ", ".join(f"{t}={s}" for t, s in mapping.joints.items())
    except UserError as e:
      r.fatal.append(str(e))
    cv = bone_length_cv(pos, motion.skeleton) * 100
    worst = motion.skeleton.joint_names[motion.skeleton.bones[int(np.argmax(cv))][1]]
    r.bone_cv = f"median {np.median(cv):.2f}%, max {cv.max():.2f}% ({worst})"
  else:
    r.mapping = "none: a marker set has no bones (train on skeletons; solve markers to joints first)"
    r.notes.append("a marker set (no skeleton): readable and drawable, not trainable as it is")
  r.up_axis, r.up_evidence = detect_up(motion, mapped)
  r.units, r.metres_per_unit, r.units_evidence = detect_units(motion, mapped, r.up_axis)
  step = np.abs(np.diff(pos, axis=0)).max(axis=(1, 2))
  r.held_frames = int(np.sum(step == 0))
  if r.held_frames:
    r.notes.append(f"{r.held_frames} frames repeat the one before exactly (dropped frames or filled gaps)")
  jumps = find_jumps(motion)
  r.teleports = len(jumps.root)
  r.notes += jumps.describe()
  r.floor, floor_notes = _floor(mapped, r.up_axis, motion.fps)
  r.notes += floor_notes
  return r


def suggest_config(reports: list[TakeReport], csv: bool) -> list[str]:
  """The ``data.*`` keys that fit the takes (each with why)."""
  ok = [r for r in reports if not r.fatal]
  if not ok:
    return []
  out = []
  ups = sorted({r.up_axis for r in ok})
  out.append(f"data.up_axis = {ups[0]!r}" + ("" if len(ups) == 1 else f"  # takes disagree: {', '.join(ups)}"))
  per = float(np.median([r.metres_per_unit for r in ok]))
  units = sorted({r.units for r in ok})
  out.append(f"data.scale = {per:.3g}  # lengths in metres ({', '.join(units)})")
  rates = sorted({r.fps for r in ok})
  if csv:
    out.append("data.fps = 30.0  # CSV records no rate: give the real one")
  if len(rates) > 1 or rates[0] > 60:
    out.append(f"data.resample_fps = 30.0  # takes at {', '.join(f'{x:g}' for x in rates)} fps")
  mapped = [r for r in ok if r.mapping and not r.mapping.startswith("none")]
  if mapped:
    out.append('data.joints = "mpii16"  # mapped ' + ", ".join(sorted({r.mapping.split(":")[0] for r in mapped})))
  else:
    out.append('data.joints = "native"')
  return out


def check_paths(specs, joint_map=None, fps: float = 30.0) -> tuple[list[TakeReport], list[str]]:
  """Reports for every take named by ``specs`` (files, folders, bundled names) and the suggested config."""
  reports, motions, csv = [], [], False
  for spec in specs:
    for f in resolve_files(spec):
      csv |= f.suffix.lower() == ".csv" and not has_sidecar(f)  # a sidecar records the rate
      try:
        motions += read_motions(f, fps=fps)
      except UserError as e:
        reports.append(TakeReport(str(f), fatal=[str(e)]))
  try:  # the mappings training would use: one per rig
    used = map_takes([m for m in motions if m.skeleton.bones], joint_map)[1]
  except UserError:
    used = {}  # some take cannot be mapped: each take on its own shows which
  fits = lambda m, u: u is not None and set(u.joints.values()) <= set(m.skeleton.joint_names) | {HEAD_TOP_FROM_EYES}
  taken = [check_take(m, joint_map, used.get(m.name) if fits(m, used.get(m.name)) else None) for m in motions]
  _compare_bodies(taken)
  reports += taken
  return reports, suggest_config(reports, csv)


PROPORTION_TOLERANCE = 0.15  # a 16-joint bone's share of the body differing by more from the takes' median


def _compare_bodies(reports) -> None:
  """Notes on the takes whose 16-joint body differs from the set's: another skeleton of the same dancer
  (CMU's BVH releases lack the ASF's thorax bone: their arms and head sit ~2 units lower) or another
  scale (a copy in metres beside one in inches)."""
  bodies = {r.path: (r, r.body) for r in reports if r.body is not None}
  if len(bodies) < 2:
    return
  sizes = {k: b.sum() for k, (_, b) in bodies.items()}
  share = np.median([b / sizes[k] for k, (_, b) in bodies.items()], axis=0)
  size = float(np.median(list(sizes.values())))
  for k, (r, b) in bodies.items():
    ratio = b / sizes[k] / share
    worst = int(np.argmax(np.abs(np.log(ratio))))
    if abs(np.log(ratio[worst])) > np.log(1 + PROPORTION_TOLERANCE):
      a, c = (MPII16.joint_names[j] for j in MPII16.bones[worst])
      r.notes.append(
        f"another body than the other takes': its {a}-{c} bone is {ratio[worst]:.2f}x their share of the body "
        "(another skeleton or export of the dancer; `data convert --like` gives takes one body size, not one skeleton)"
      )
    if abs(np.log(sizes[k] / size)) > np.log(1.5):
      r.notes.append(f"{sizes[k] / size:.3g}x the size of the other takes' bodies (another unit?)")
