"""Takes -> ids, train/validation split, fitted features and deterministic window batches.

A dataset is a bundled name (``cmu94``), a folder of takes, or a single file. Each take gets a stable
integer id from the sorted order of the file names; the id map travels with every run.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence
from importlib import resources
from pathlib import Path

import jax
import numpy as np

from chorjax.data import formats, transforms
from chorjax.data.cache import Cache, cache_root, in_processes, workers_for
from chorjax.data.features import Features, feature_dim, floor_height, takes_joint_pace
from chorjax.data.labels import Labels, read_labels, search_name, take_condition
from chorjax.data.mapping import map_takes
from chorjax.data.motion import Motion, bone_lengths
from chorjax.data.rest import drop_leading_rests
from chorjax.data.transforms import to_up_axis
from chorjax.errors import UserError

BUNDLED = ("cmu94",)


def bundled_path(name: str) -> Path:
  """The folder of a bundled dataset inside the installed package."""
  return Path(str(resources.files("chorjax.data") / "bundled" / name))


def resolve_files(spec: str) -> list[Path]:
  """A bundled name, a folder or a file -> the sorted list of take files."""
  path = bundled_path(spec) if spec in BUNDLED else Path(spec)
  head, _, rest = spec.partition("/")
  if not path.exists() and head in BUNDLED and rest:  # e.g. cmu94/94_10_skeleton_3d.csv
    path = bundled_path(head) / rest
  if path.is_dir():
    readable = formats.suffixes("read")
    files = sorted(p for p in path.iterdir() if p.suffix.lower() in readable)
    if not files:
      raise UserError(f"{path}: no motion files ({', '.join(readable)}) in this folder")
    return files
  if path.is_file():
    return [path]
  if path.exists():
    raise UserError(f"{path}: not a regular file (a pipe or a device); motion files are read whole")
  hint = f" (bundled datasets: {', '.join(BUNDLED)})"
  raise UserError(f"{spec}: no such file, folder or bundled dataset{hint}")


def read_motions(
  path: Path, *, skeleton: str = "mpii16", fps: float = 30.0, up_axis: str = "-y", asf=None, amc_fps: float = 120.0
) -> list[Motion]:
  """Reads every motion in a file: one for a take, K for a sample ``.npz`` of K dancers.

  CSV takes use ``skeleton``, ``fps`` and ``up_axis`` (CSV records none of them); BVH, ASF/AMC, C3D
  and NPZ files carry their own. An AMC finds its skeleton by ``asf``, else by ``amc.find_asf``;
  AMC files do not record their rate: ``amc_fps`` (120, the CMU rate, unless told).
  """
  reading = formats.Reading(skeleton=skeleton, fps=fps, up_axis=up_axis, asf=asf, amc_fps=amc_fps)
  return formats.read(path, reading)


def read_takes(specs: Sequence[str], data_cfg=None, cache: Cache | None = None) -> list[Motion]:
  """Reads every take named by ``specs`` (bundled names, folders or files); with a ``cache``, a file read
  before (the same bytes, the same settings) is not parsed again."""
  kw = {} if data_cfg is None else {"skeleton": data_cfg.skeleton, "fps": data_cfg.fps, "up_axis": data_cfg.up_axis}
  cache = cache or Cache(None)
  files = [f for spec in specs for f in resolve_files(spec)]
  if cache.root is not None and data_cfg is not None:  # a library's new files: parsed in processes, then read back
    missing = [f for f in files if not cache.has_motions(f, kw)]
    workers = workers_for(data_cfg.workers, len(missing))
    if workers > 1:
      in_processes(functools.partial(_read_into, root=cache.root, settings=kw), missing, workers)
  return [m for f in files for m in cache.motions(f, kw, lambda f=f: read_motions(f, **kw))]


def _read_into(path: Path, root: Path, settings: dict) -> None:
  """A worker of :func:`read_takes`: parses one file into the cache."""
  Cache(root).motions(path, settings, lambda: read_motions(path, **settings))


def to_rate(motion: Motion, fps: float) -> Motion:
  """The same motion at another frame rate (linear interpolation; unchanged at its own rate)."""
  if motion.fps == fps:
    return motion
  return motion.replace(
    positions=np.asarray(
      transforms.resample(motion.positions, motion.fps, fps, motion.source or motion.name), np.float32
    ),
    fps=fps,
  )


def one_rate(motions: Sequence[Motion], seq_length: int) -> tuple[list[Motion], float, list[str]]:
  """Takes at one frame rate (mixed rates: the most common one, ties to the higher), and notes for the
  user: which takes were resampled, and when a training window lasts under a second."""
  rates = [m.fps for m in motions]
  fps = max(set(rates), key=lambda r: (rates.count(r), r))
  notes = []
  if len(set(rates)) > 1:
    mixed = ", ".join(f"{rates.count(r)} at {r:g} fps" for r in sorted(set(rates)))
    notes.append(f"takes of mixed frame rates ({mixed}): resampled to {fps:g} fps (data.resample_fps chooses)")
  if seq_length / fps < 1.0:
    fix = f"data.resample_fps = 30 makes it {seq_length / 30:.2g} s, or " if fps > 30 else ""
    notes.append(
      f"note: a training window of {seq_length} frames lasts {seq_length / fps:.2g} s at {fps:g} fps "
      f"(a phrase of dance lasts seconds); {fix}lengthen data.seq_length"
    )
  return [to_rate(m, fps) for m in motions], fps, notes


def conform(
  motions: Sequence[Motion], data_cfg, mappings: dict | None = None, notes: list | None = None, *, rest: bool = True
) -> list[Motion]:
  """Brings takes of any format into the dataset's layout: without a leading rest pose (unless
  ``data.keep_rest_frames``; ``rest=False`` keeps frame numbers as in the file), joints (``data.joints``,
  mapped as ``chorjax.data.mapping`` decides; the mappings used are put into ``mappings``) and up axis.
  What the user should know goes into ``notes``."""
  out = list(motions)
  if rest and not data_cfg.keep_rest_frames:
    out, note = drop_leading_rests(out)
    if note and notes is not None:
      notes.append(note)
  if data_cfg.joints == "mpii16":
    out, used = map_takes(out, data_cfg.joint_map or None)
    if mappings is not None:
      mappings.update(used)
  out = [to_up_axis(m, data_cfg.up_axis) for m in out]
  if data_cfg.resample_fps:
    out = [to_rate(m, data_cfg.resample_fps) for m in out]
  names = {m.skeleton.joint_names for m in out}
  if len(names) > 1:
    raise UserError(f"{data_cfg.dataset}: takes have different skeletons; use data.joints='mpii16' to map them")
  return out


@dataclasses.dataclass(frozen=True, eq=False)
class Dataset:
  """The takes of a run, split and encoded.

  Attributes:
    id_map: what conditions the model -> its index: each take's name (sorted names), or with ``data.labels``
      each ``field=value`` (saved with every run).
    motions: the raw takes, in id order.
    train_names, val_names: the split.
    features: the feature pipeline fitted on the training split.
    train: ``(condition, features [T, D])`` per training sequence, augmentations included (condition: the
      take's id, or with labels its weights ``[M]``).
    val: the same for the held-out takes (no augmentation).
    mappings: take name -> the ``Mapping`` that put it on the 16-joint layout (mapped takes only).
    fps: the frame rate every take was brought to (``one_rate``).
    notes: what the user should know about the takes (resampling, short windows).
    labels: the named labels that condition the run (``data.labels``), or None (one id per take).
    augment: what the training takes went through: ``data.augment``, less the mirror under ``data.keep_side``.
  """

  id_map: dict
  motions: tuple
  train_names: tuple
  val_names: tuple
  features: Features
  train: tuple
  val: tuple
  mappings: dict = dataclasses.field(default_factory=dict)
  fps: float = 30.0
  notes: tuple = ()
  labels: Labels | None = None
  augment: tuple = ()

  @property
  def num_motions(self) -> int:
    return len(self.id_map)

  def condition(self, take: int):
    """What conditions the model on take number ``take`` (in reading order): its id, or its labels' weights."""
    return take_condition(self.labels, self.id_map, self.motions[take].name)


def _val_names(names: list[str], val_takes: Sequence, val_pattern: str = "") -> list[str]:
  if val_pattern:
    if tuple(val_takes) != ("auto",):
      raise UserError("data.val_pattern: set it or data.val_takes, not both")
    out = [n for n in names if search_name(val_pattern, n, "data.val_pattern")]
    if not out:
      raise UserError(f"data.val_pattern: {val_pattern!r} finds no take; takes: {_some(names)}")
  elif tuple(val_takes) == ("auto",):
    return names[-1:] if len(names) > 1 else []
  else:
    out = [_val_name(names, v) for v in val_takes]
  if len(out) == len(names):
    key = "data.val_pattern" if val_pattern else "data.val_takes"
    raise UserError(f"{key}: holds out every take; nothing is left to train on")
  return out


def _val_name(names: list[str], v) -> str:
  if isinstance(v, int):
    if not 0 <= v < len(names):
      raise UserError(f"data.val_takes: id {v} out of range (0..{len(names) - 1})")
    return names[v]
  if v not in names:
    raise UserError(f"data.val_takes: no take named {v!r}; takes: {_some(names)}")
  return v


def _some(names: list[str], most: int = 12) -> str:
  return ", ".join(names[:most]) + (f" ... ({len(names)} takes)" if len(names) > most else "")


def load_dataset(data_cfg) -> Dataset:
  """Reads, splits, fits normalization on the training split, and encodes every take.

  Raises:
    UserError: for unreadable files, an empty selection, or no take as long as one window (shorter takes
      are left out, and ``notes`` says which).
  """
  # Full float32 products: on a GPU, JAX's default multiplies float32 matrices in TF32, and the features of a
  # run trained there differed from the same takes read on a CPU by up to 1e-3 (2% of a feature's std), so
  # sampling it elsewhere refused its training data as changed. On a CPU this changes nothing.
  with jax.default_matmul_precision("highest"):
    return _load_dataset(data_cfg)


def _encoding(proto: Features, augment) -> dict:
  """The settings a take's encoding depends on (with its positions, skeleton and rate: ``Cache.encoded``)."""
  return {
    "representation": proto.representation,
    "up_axis": proto.up_axis,
    "scale": proto.scale,
    "augment": list(augment),
  }


def _encode_into(motion: Motion, proto: Features, augment, root: Path) -> None:
  """A worker of :func:`_load_dataset`: encodes one take into the cache."""
  _encoded(motion, proto, augment, Cache(root))


def _encode_missing(motions, proto: Features, augment, workers: int, cache: Cache) -> None:
  """A library's takes not yet encoded in the cache, encoded in processes (``data.workers``): encoding compiles
  once per take length, and a library has hundreds of lengths."""
  if cache.root is None:
    return
  settings = _encoding(proto, augment)
  # by length: a worker gets takes of neighbouring lengths and compiles each length once, not every worker
  missing = sorted((m for m in motions if not cache.has_encoded(m, settings)), key=lambda m: m.num_frames)
  if (workers := workers_for(workers, len(missing))) > 1:
    encode = functools.partial(_encode_into, proto=proto, augment=augment, root=cache.root)
    in_processes(encode, missing, workers)


def _encoded(motion: Motion, proto: Features, augment, cache: Cache) -> dict:
  """A take's canonical positions (``canon``) and its encoded versions (``version0``: as it is, then the
  augmentations), made once and kept in ``cache``."""

  def make() -> dict:
    canon = np.asarray(proto.canonical(motion.positions))
    out = [canon]
    if "mirror" in augment:
      out.append(np.asarray(transforms.mirror(canon, motion.skeleton.twins, lateral_axis=0)))
    if "reverse" in augment:
      out += [np.asarray(transforms.reverse_time(c)) for c in out]
    return {"canon": canon, **{f"version{k}": np.asarray(proto.represent(c)) for k, c in enumerate(out)}}

  def check(arrays: dict) -> dict:  # an entry holding another take's arrays under this one's key is not used
    # proto.canonical in numpy: no program compiled per take length when a library's entries are read
    canon = np.einsum("ij,...j->...i", transforms.up_axis_matrix(proto.up_axis), motion.positions) * proto.scale
    sizes = {len(v) for k, v in arrays.items() if k.startswith("version")}
    held = arrays.get("canon")
    if held is None or held.shape != canon.shape or sizes != {len(canon)} or not np.allclose(held, canon, atol=1e-4):
      raise ValueError("holds another take's arrays")
    return arrays

  return cache.encoded(motion, _encoding(proto, augment), make, check)


def _load_dataset(data_cfg) -> Dataset:
  mappings: dict = {}
  rest_notes: list[str] = []
  cache = Cache(cache_root(data_cfg.cache))
  motions = conform(read_takes([data_cfg.dataset], data_cfg, cache), data_cfg, mappings, rest_notes)
  motions, fps, notes = one_rate(motions, data_cfg.seq_length)
  loop = round(data_cfg.loop * fps)  # data.loop in frames
  motions, usable_notes = _usable(motions, data_cfg, loop)
  notes = rest_notes + notes + usable_notes
  names = [m.name for m in motions]
  labels = read_labels(data_cfg.labels, names) if data_cfg.labels else None
  id_map = {n: i for i, n in enumerate(labels.names if labels else names)}
  val_names = _val_names(names, data_cfg.val_takes, data_cfg.val_pattern)
  train_names = [n for n in names if n not in val_names]
  val_names, short_notes = _long_enough(val_names, motions, data_cfg)
  notes += short_notes
  motions, tails = with_tails(motions, train_names, data_cfg)
  by_name = {m.name: m for m in [*motions, *tails]}
  val_names = [*val_names, *(t.name for t in tails)]
  names = [*names, *(t.name for t in tails)]
  condition = lambda n: take_condition(labels, id_map, n.removesuffix(TAIL))

  skeleton = motions[0].skeleton
  augment, side_notes = _sides([by_name[n].positions for n in train_names], skeleton, data_cfg)
  notes += side_notes
  proto = Features(
    skeleton,
    data_cfg.representation,
    data_cfg.up_axis,
    data_cfg.scale,
    np.zeros(feature_dim(skeleton, data_cfg.representation), np.float32),
    np.ones(feature_dim(skeleton, data_cfg.representation), np.float32),
  )
  _encode_missing(list(by_name.values()), proto, augment, data_cfg.workers, cache)
  encoded = {n: _encoded(by_name[n], proto, augment, cache) for n in names}
  # the training takes' mean bone lengths: `directions` builds every frame with them, rigid decoding too
  canon = [encoded[n]["canon"] for n in train_names]
  lengths = np.zeros(skeleton.num_joints, np.float32)
  lengths[[c for _, c in skeleton.bones]] = np.concatenate([bone_lengths(c, skeleton) for c in canon]).mean(0)
  floor = floor_height(canon, skeleton) if data_cfg.representation == "canonical" else None
  proto = dataclasses.replace(proto, lengths=lengths, floor=floor)
  versions = {n: [v for k, v in sorted(encoded.pop(n).items()) if k.startswith("version")] for n in names}
  train_raw = [(condition(n), looped(x, loop)) for n in train_names for x in versions[n]]
  val_raw = [(condition(n), versions[n][0]) for n in val_names]
  del versions, canon  # the raw versions live on in train_raw / val_raw alone, each let go once normalized
  stats = transforms.merged_stats([x for _, x in train_raw])
  # Root-motion representations hold features that are constant by construction (the hips' depth in
  # the facing frame, the root's direction slot): a floor keeps float noise in them from being blown up.
  floor = 1e-3 if data_cfg.representation in ("canonical", "directions") else 1e-8
  std = stats.std(ddof=1, floor=floor).astype(np.float32)
  features = dataclasses.replace(proto, mean=stats.mean.astype(np.float32), std=std)
  train = _normalized(train_raw, features)
  features = _generation_stats(features, train, fps)
  return Dataset(
    id_map,
    tuple(motions),
    tuple(train_names),
    tuple(val_names),
    features,
    train,
    _normalized(val_raw, features),
    mappings,
    fps,
    tuple(notes),
    labels,
    augment,
  )


def _normalized(raw: list, features: Features) -> tuple:
  """``raw``'s ``(condition, frames)`` in the features' normalized units, each raw take let go from ``raw``
  once its normalized copy is made: a library is held once, not twice."""
  out = []
  for k, (i, x) in enumerate(raw):
    z = x - features.mean
    z /= features.std
    out.append((i, z.astype(np.float32, copy=False)))
    raw[k] = None
  return tuple(out)


TAIL = " (tail)"  # a take's last frames held out (data.val_tail): the take's name and this


def window(data_cfg) -> int:
  """Frames in one training window: ``data.seq_length`` inputs and the frame after the last."""
  return data_cfg.seq_length + 1


def with_tails(motions: Sequence, train_names: Sequence[str], data_cfg) -> tuple[list, list]:
  """``(motions, tails)``: with ``data.val_tail``, each training take's last share of frames (at least one
  window: ``data.seq_length + 1``) cut off as a take of its own named ``NAME (tail)``, the take keeping the
  rest; without it, the motions as they are and no tails. A take too short to give both a window is refused."""
  share, need = data_cfg.val_tail, window(data_cfg)
  if not share:
    return list(motions), []
  heads, tails, trained = [], [], set(train_names)
  for m in motions:
    if m.name not in trained:
      heads.append(m)
      continue
    cut = m.num_frames - max(round(m.num_frames * share), need)
    if cut < need:
      raise UserError(
        f"{m.source or m.name}: {m.num_frames} frames; data.val_tail = {share:g} needs at least {2 * need} "
        f"(a window to train on and one to validate on; data.seq_length + 1 = {need} each)"
      )
    heads.append(m.replace(positions=m.positions[:cut]))
    tails.append(m.replace(positions=m.positions[cut:], name=m.name + TAIL))
  return heads, tails


def looped(x: np.ndarray, frames: int) -> np.ndarray:
  """A take's encoded frames ``x`` played back to back until at least ``frames`` long (``data.loop``); a take
  that long already, as it is. In root-motion features (canonical) the seam's frame takes no step: the root
  does not jump back, only the pose goes from the take's last frame to its first (a short take's both stand)."""
  return np.concatenate([x] * -(-frames // len(x))) if len(x) < frames else x


def _long_enough(val_names: list[str], motions, data_cfg) -> tuple[list[str], list[str]]:
  """``(the held-out takes at least one window long, a note naming how many are not)``: with ``data.loop``,
  shorter takes are kept to train on, and those held out are left out of validation."""
  need, frames = window(data_cfg), {m.name: m.num_frames for m in motions}
  short = [n for n in val_names if frames[n] < need]
  if not short:
    return val_names, []
  line = f"note: {len(short)} held-out takes are shorter than one window ({need} frames) and are not validated on"
  return [n for n in val_names if n not in short], [line]


def _usable(motions, data_cfg, loop: int) -> tuple[list, list[str]]:
  """The takes training can use and what to say about the others: a UserError for two takes of one name, for
  no take as long as a window, or none that moves; takes shorter than a window are left out, with a warning
  naming them (a library's short takes), unless ``data.loop`` makes them a window long; a warning per take that
  does not move. ``loop``: ``data.loop`` in frames."""
  names = [m.name for m in motions]
  if len(set(names)) != len(names):
    raise UserError(f"{data_cfg.dataset}: two takes share a name; ids come from file names")
  need = window(data_cfg)
  what, keep = f"one window (data.seq_length + 1 = {need} frames)", "; a shorter data.seq_length keeps them"
  if loop >= need:  # looped up to a window: a take needs a step to loop
    need, what, keep = 2, "two frames (data.loop plays a take back to back)", ""
  short = [m for m in motions if m.num_frames < need]
  if len(short) == len(motions):
    m = short[0]
    raise UserError(f"{m.source}: {m.num_frames} frames, shorter than {what}")
  notes = []
  if short:
    which = ", ".join(f"{m.name} ({m.num_frames})" for m in short[:3]) + (" ..." if len(short) > 3 else "")
    notes.append(
      f"warning: {len(short)} of {len(motions)} takes are shorter than {what} and are left out: {which}{keep}"
    )
    motions = [m for m in motions if m.num_frames >= need]
  frozen = [m.name for m in motions if not np.ptp(m.positions, axis=0).max() > 0]
  if frozen and len(frozen) == len(motions):
    raise UserError(f"{data_cfg.dataset}: no take moves (every frame of each is one pose): nothing to learn")
  notes += [f"warning: take {n} does not move (every frame is one pose): remove it unless you mean it" for n in frozen]
  return motions, notes


ONE_SIDED = 1.5  # a twin joint this much faster than its twin: the dancer favours one side


def _sides(train, skeleton, data_cfg) -> tuple[tuple, list[str]]:
  """``data.augment`` as the training takes (``[T, J, 3]`` each, in any frame) go through it, less the mirror
  under ``data.keep_side`` when they favour one side (``ONE_SIDED``), and a note saying so."""
  augment = tuple(data_cfg.augment)
  if "mirror" not in augment:
    return augment, []
  joint, ratio = transforms.favoured_side(train, skeleton.twins)
  if ratio < ONE_SIDED:
    return augment, []
  name, twin = skeleton.joint_names[joint], skeleton.joint_names[skeleton.twins[joint]]
  said = f"note: the training takes favour one side ({name} moves {ratio:.1f}x as fast as {twin})"
  if data_cfg.keep_side:
    kept = "not mirrored (data.keep_side), so the model keeps the dancer's side; data.keep_side = false mirrors them"
    return tuple(a for a in augment if a != "mirror"), [f"{said}: {kept} (experiments/draw: CMU 131)"]
  both = "mirrored copies teach the model both sides, and it dances them alike; data.keep_side = true keeps its side"
  return augment, [f"{said}: {both} (experiments/draw: CMU 131)"]


SMALL_DATA_MINUTES = 3.0  # below this much training motion, training says what to expect (experiments/dancers)


def dataset_notes(ds: Dataset) -> list[str]:
  """What a user should know about the dataset before training: how each skeleton was mapped onto the
  16-joint layout, the frame rate, what to expect from little motion, and a warning when nothing is held
  out for validation."""
  out: list[str] = []
  by_method: dict[str, list[str]] = {}
  for name, m in ds.mappings.items():
    by_method.setdefault(m.describe(), []).append(name)
  for how, names in by_method.items():
    takes = names[0] if len(names) == 1 else f"{names[0]} and {len(names) - 1} more"
    out.append(f"joints of {takes} mapped {how}")
  out += ds.notes
  if ds.labels is not None:
    fields = "; ".join(
      f"{f} ({len(v)}): {', '.join(v[:8])}{' ...' if len(v) > 8 else ''}" for f, v in ds.labels.fields.items()
    )
    out.append(f"conditioned on labels (data.labels), not take ids: {fields}")
  trained = set(ds.train_names)
  minutes = sum(len(m.positions) for m in ds.motions if m.name in trained) / ds.fps / 60
  if minutes < SMALL_DATA_MINUTES:
    out.append(
      f"note: {minutes:.1f} minutes of training motion: on the dancers benchmark, sets under "
      f"{SMALL_DATA_MINUTES:g} minutes keep dancing with the quickstart, martial arts (1.3) at its held-out takes' "
      "movement (every 1,000 frames 0.72-1.19) a little faster than them (speed 1.01-1.16), CMU 5 and 131 (0.5) "
      "calmer (their calmest 1,000 frames at 0.64-0.76, root travel 0.76-0.95 of the held-out take's); more takes "
      "help most (README: How well it dances)"
    )
  if not ds.val_names:
    why = "a single take" if len(ds.motions) == 1 else "data.val_takes = []"
    out.append(
      f"warning: no validation split ({why}): val_loss is not measured and cannot show overfitting; "
      "add a take or name one in data.val_takes"
    )
  return out


def _generation_stats(features: Features, train, fps: float) -> Features:
  """What generation may hold to: the range the encoded training frames span (``sample.clamp``), the range
  of their changes from one frame to the next (``sample.clamp_steps``) and their pace, how far the pose
  features move in half a second (``sample.pace``)."""
  lag = max(round(0.5 * fps), 1)
  pose = features.pose_channels
  moved = [np.abs(x[lag:, pose] - x[:-lag, pose]).mean(-1) for _, x in train if len(x) > lag]
  pace = float(np.concatenate(moved).mean())
  joints = features.joint_motion
  if joints is not None:  # the same as the judge measures it: joints relative to the root, turning included
    moved = takes_joint_pace([x for _, x in train if len(x) > lag], lag, joints)
  steps = [np.diff(x, axis=0) for _, x in train if len(x) > 1]
  labelled = [c for c, x in train if len(x) > lag and isinstance(c, np.ndarray)]
  # per take, then over takes: no copy of every frame at once (a library's hours of motion)
  return dataclasses.replace(
    features,
    pace_by_label=label_pace(labelled, moved) if labelled else None,
    low=np.min([x.min(0) for _, x in train], 0),
    high=np.max([x.max(0) for _, x in train], 0),
    step_low=np.min([d.min(0) for d in steps], 0),
    step_high=np.max([d.max(0) for d in steps], 0),
    pace_lag=lag,
    pace=pace,
    pace_joints=None if joints is None else float(np.concatenate(moved).mean()),
  )


def label_pace(weights: Sequence[np.ndarray], moved: Sequence[np.ndarray]) -> np.ndarray:
  """``Features.pace_by_label``: one row per distinct label combination of the training takes (take k: label
  weights ``weights[k]`` ``[M]``, its movement over the lag ``moved[k]``): the weights ``[M]`` and the log of
  their takes' pace (every frame weighing alike), ``[K, M + 1]``."""
  rows: dict = {}
  for w, m in zip(weights, moved):
    total, n = rows.get(w.tobytes(), (0.0, 0))
    rows[w.tobytes()] = (total + float(m.sum()), n + len(m))
  floor = 1e-3 * sum(t for t, _ in rows.values()) / sum(n for _, n in rows.values())  # a pair that stands still
  dtype = np.asarray(weights[0]).dtype
  out = [np.r_[np.frombuffer(k, dtype), np.log(max(t / n, floor))] for k, (t, n) in rows.items()]
  return np.stack(out).astype(np.float32)


class WindowSampler:
  """Deterministic random windows: batch ``step`` depends only on (seed, step).

  A batch holds ``batch_size`` windows of ``seq_length + 1`` frames; the sequence is chosen with
  probability proportional to its length, the start uniformly. Inputs are frames t..t+L-1, targets
  t+1..t+L. Because nothing is carried between steps, the "sampler position" is the step number,
  and resuming at step s reproduces the uninterrupted run exactly.
  """

  def __init__(
    self, sequences: Sequence[tuple[int | np.ndarray, np.ndarray]], seq_length: int, batch_size: int, seed: int
  ):
    if not sequences:
      raise UserError("no training sequences")
    self.seq_length, self.batch_size, self.seed = seq_length, batch_size, seed
    self.ids = conditions([i for i, _ in sequences])
    lengths = np.array([x.shape[0] for _, x in sequences])
    self.sequences = [np.asarray(x, np.float32) for _, x in sequences]  # the takes' own arrays: no second copy
    self.max_start = lengths - (seq_length + 1)
    self.probs = lengths / lengths.sum()

  def indices(self, step: int) -> tuple[np.ndarray, np.ndarray]:
    """(sequence index [B], start frame [B]) of batch ``step``."""
    rng = np.random.default_rng((self.seed, step))
    seq = rng.choice(len(self.ids), size=self.batch_size, p=self.probs)
    start = (rng.random(self.batch_size) * (self.max_start[seq] + 1)).astype(np.int64)
    return seq, start

  def batch(self, step: int, rows: slice = slice(None)) -> dict[str, np.ndarray]:
    """Batch ``step`` (optionally only some rows: one process's share of a global batch)."""
    seq, start = self.indices(step)
    seq, start = seq[rows], start[rows]
    frames = np.stack([self.sequences[q][s : s + self.seq_length + 1] for q, s in zip(seq, start)])
    return {"inputs": frames[:, :-1], "targets": frames[:, 1:], "motion_ids": self.ids[seq]}


def eval_windows(sequences: Sequence[tuple[int | np.ndarray, np.ndarray]], seq_length: int, max_windows: int) -> dict:
  """Fixed validation windows: non-overlapping, in order, at most ``max_windows``."""
  frames, ids = [], []
  for i, x in sequences:
    for s in range(0, x.shape[0] - seq_length, seq_length):
      frames.append(x[s : s + seq_length + 1])
      ids.append(i)
  if not frames:
    return {}
  # Spread the kept windows evenly over all takes instead of taking the first ones.
  keep = np.unique(np.linspace(0, len(frames) - 1, min(max_windows, len(frames))).astype(int))
  frames = np.stack([frames[k] for k in keep])
  return {"inputs": frames[:, :-1], "targets": frames[:, 1:], "motion_ids": conditions([ids[k] for k in keep])}


def conditions(items: Sequence) -> np.ndarray:
  """Take ids ``[N]`` (int32), or label weights ``[N, M]`` (float32): what the model reads as ``motion``."""
  if items and isinstance(items[0], np.ndarray):
    return np.stack(items).astype(np.float32)
  return np.array(items, np.int32)
