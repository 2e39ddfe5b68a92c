"""Run configuration: TOML files -> frozen dataclasses; the schema below IS the documentation.

An unknown key, a wrong type or a value outside its allowed set is a ``UserError`` naming the file,
the line and the key, and suggesting the closest valid key. Dotted overrides such as
``model.cell=gru`` are parsed as TOML values (falling back to a bare string) and checked the same way.
"""

from __future__ import annotations

import dataclasses
import difflib
import json
import math
import re
import tomllib
import typing
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from chorjax.errors import UserError, check_draw, check_memory, load_toml, read_text
from chorjax.fields import config_field as _field
from chorjax.registry import family_of
from chorjax.registry import names as family_names
from chorjax.registry import sections as family_sections
from chorjax.sampling.table import ControlFields


def field_choices(meta, registered: bool = True) -> tuple | None:
  """A field's allowed values (``meta``: its metadata); a callable's are read now (the families, with those
  registered in this process where ``registered``)."""
  choices: Any = meta.get("choices")
  if callable(choices):
    return tuple(typing.cast(Sequence, choices(registered)))
  return tuple(choices) if choices else None


@dataclasses.dataclass(frozen=True)
class DataConfig:
  dataset: str = _field("cmu94", "a bundled dataset name (cmu94), a folder of takes, or one file")
  skeleton: str = _field(
    "mpii16",
    "joint layout of CSV takes: mpii16, or a FILE.skeleton.json (a sidecar beside a CSV is found by itself)",
    more=("`chorjax data convert --joints native` writes such a sidecar beside each CSV."),
  )
  joints: str = _field(
    "mpii16",
    "train on the 16-joint layout (BVH/ASF/AMC takes are mapped by joint name) or on the files' own skeleton",
    choices=("mpii16", "native"),
  )
  joint_map: str = _field(
    "",
    "a TOML file mapping each training joint to a source joint, for skeletons that cannot be placed automatically",
    more=(
      'One `target = "source joint"` line per training joint. Without it, skeletons are placed by a known '
      "rig family, by joint names, then by topology."
    ),
  )
  fps: float = _field(30.0, "frame rate of CSV takes (CSV files do not record it), 1-1000", minimum=1.0, below=1000.5)
  resample_fps: float = _field(
    0.0,
    "resample every take to this frame rate after reading, any format (0 = keep the files' rates; "
    "takes of mixed rates go to the most common one)",
    minimum=0.0,
    below=1000.5,
  )
  up_axis: str = _field(
    "-y", "signed up axis of the files (cmu94: -y, y points down)", choices=("y", "-y", "z", "-z", "x", "-x")
  )
  scale: float = _field(0.01, "multiplies lengths before training (cmu94 units: thigh ~94)", minimum=1e-12)
  representation: str = _field(
    "bone_relative",
    "features the model sees: absolute, bone_relative, root_relative, canonical (root motion + pose) or directions",
    more=(
      "canonical: HumanML3D-style (facing frame, joint steps, foot contacts); directions: unit bone "
      "directions at the training takes' mean lengths, so bones cannot stretch."
    ),
    choices=("absolute", "bone_relative", "root_relative", "canonical", "directions"),
  )
  seq_length: int = _field(100, "frames per training window (inputs; targets are shifted by one)", minimum=1)
  val_takes: tuple = _field(("auto",), "held-out take names; 'auto' = the last take by name; [] = none")
  val_pattern: str = _field(
    "",
    "held out instead: every take whose name the pattern finds (e.g. a trial of each label: '_001$')",
    more="A regular expression searched in take names, as `data.labels`'s; `data.val_takes` then stays `auto`.",
  )
  val_tail: float = _field(
    0.0,
    "also hold out the last share of every training take (e.g. 0.2): frames to validate on from a single take",
    more=(
      'The kept checkpoint (`train.keep = "best"`) is then chosen on frames the model never trained on, cut from '
      "the takes themselves; `chorjax eval --data held-out` judges on those frames too. Each tail is at least "
      "one window long."
    ),
    minimum=0.0,
    below=0.5,
  )
  cache: str = _field(
    "auto",
    "where read and encoded takes are kept, so a library is read once: auto (~/.cache/chorjax), off, or a folder",
    resumable=True,
    more=(
      "`auto` is `$CHORJAX_CACHE`, else `$XDG_CACHE_HOME/chorjax`, else `~/.cache/chorjax`. An entry is keyed "
      "by the file's path and bytes and the settings that read and encode it: a changed take is read again, "
      "alone; a damaged entry is made again, with one line saying so. chorjax never deletes it."
    ),
  )
  workers: int = _field(
    0,
    "processes that read and encode takes not yet in the cache: 0 = every core when there are 64 or more, else 1",
    minimum=0,
    resumable=True,
  )
  labels: str = _field(
    "",
    "condition on named labels, not take ids: a pattern with named groups over take names, or a take,FIELD CSV",
    more=(
      "A TOML literal string keeps the backslashes: `labels = '_(?P<action>[^_]+)_(?P<style>[^_]+)_\\d+$'`. "
      "Each group is a field (its own embedding); `--motion action=walk,style=elderly` and `--mix "
      "style=elderly:0.5,style=active:0.5` pick them. Empty: one id per take."
    ),
  )
  keep_rest_frames: bool = _field(
    False,
    "keep a take's leading rest pose (by default training drops it and says so)",
    more=(
      "A converter's arms-out frame 0 and the blend out of it are found by the jump they make (`chorjax "
      "data check` shows them)."
    ),
  )
  augment: tuple = _field(
    (), "training augmentations: 'reverse' (time) and/or 'mirror' (left/right)", choices=("reverse", "mirror")
  )


@dataclasses.dataclass(frozen=True)
class ModelConfig:
  family: str = _field(
    "rnn",
    "model family: 'rnn' (recurrent core + head), 'gan' (LSTM-GAN, [gan]) or 'inbetween' (transitions, [inbetween])",
    more=(
      "rnn predicts every next frame through model.head; gan's generator turns a noise vector into a whole "
      "sequence that a critic judges; inbetween writes the frames between a context phrase and a target "
      "pose for `chorjax inbetween`, its core being model.cell, num_layers, hidden_size and forget_bias."
    ),
    choices=family_names,
  )
  cell: str = _field("lnlstm", "recurrent cell", choices=("lstm", "lnlstm", "gru"))
  head: str = _field("mdn", "output head", choices=("mse", "mdn"))
  num_layers: int = _field(3, "stacked recurrent layers", minimum=1)
  hidden_size: int = _field(256, "units per layer", minimum=1)
  num_mixtures: int = _field(8, "MDN mixture components", minimum=1)
  mdn_scale: str = _field(
    "diagonal", "MDN scales: one per dim, or one per component (chor-rnn)", choices=("diagonal", "isotropic")
  )
  mdn_basis: str = _field(
    "features",
    "the MDN's coordinates: 'features', 'pca' (the training frames' principal axes) or 'acceleration' (their"
    " accelerations')",
    more=(
      "With 'pca' or 'acceleration' the basis is fixed at the start of training and saved with the run. 'pca': "
      "a draw varies the pose along directions the data varies together. 'acceleration': for an MDN that "
      "carries its residuals (`model.mdn_memory`), whose scales are what the frame adds to the motion so far, "
      "the directions the dancer's motion changes together. The likelihood is the same quantity (the basis is a "
      "rotation); an MSE head ignores the key."
    ),
    choices=("features", "pca", "acceleration"),
  )
  mdn_memory: int = _field(
    0,
    "frames of residuals (frame minus a component's mean) the MDN carries into each frame's means: 0 = white noise",
    more=(
      "The residuals follow an autoregression of that order whose partial autocorrelations (one per lag and "
      "coordinate, in (-1, 1)) the network predicts and every component shares, so a draw's residuals may wander "
      "(with 2, as a velocity that keeps on) but never grow without bound; the scales are what is left. Still an "
      "MDN sampled frame by frame, with an exact likelihood: the noise continues over frames as the model learned "
      "it does, not as a filter set afterwards (`experiments/draw/`)."
    ),
    minimum=0,
    below=4,  # lags 1-3: where the residual was, where it was heading and how that was turning
  )
  mdn_carry: str = _field(
    "free",
    "how the carried residuals may move (model.mdn_memory): 'free', or 'smooth' (they never tremble)",
    more=(
      "'free': each lag's partial autocorrelation anywhere in (-1, 1). 'smooth': the autoregression's "
      "polynomial at -1 kept at least 1, lag by lag, so the residuals gain no power at the highest frequency: "
      "they may wander, keep a velocity or turn, but not flip sign frame to frame as marker wobble does."
    ),
    choices=("free", "smooth"),
  )
  min_scale: float = _field(1e-3, "floor of MDN scales (normalized units)", minimum=0.0)
  dropout: float = _field(0.0, "dropout rate between layers (same mask at every time step)", minimum=0.0, below=1.0)
  forget_bias: float = _field(1.0, "initial forget-gate bias of (LN-)LSTM cells (notebook: 5.0)")
  initial_state: str = _field(
    "motion", "initial (c, h): projected motion-id weights, or zeros", choices=("motion", "zero")
  )
  condition_every_frame: bool = _field(
    False,
    "the motion weights (take ids or labels) enter every frame's input too, not only the initial state",
    more=(
      "An initial state fades within seconds of free-running generation; a library's labels (`data.labels`) "
      "have to hold for the whole dance. Recurrent family only."
    ),
  )
  lstm_kernel: str = _field(
    "fused",
    "how model.cell = 'lstm' runs: 'fused' (every backend) or 'cudnn' (cuDNN on a CUDA GPU, fused elsewhere)",
    more=(
      "'cudnn' uses NVIDIA cuDNN through jax.experimental.rnn with the same parameters as the fused scan, "
      "so a run trained on a GPU samples anywhere."
    ),
    choices=("fused", "cudnn"),
  )

  @property
  def memory(self) -> int:
    """Frames of residuals the MDN carries into each frame (``model.mdn_memory``; an MSE head has no noise)."""
    return self.mdn_memory if self.head == "mdn" else 0

  @property
  def pca_basis(self) -> bool:
    """Whether the MDN lives in a fixed basis of principal axes, the frames' or their accelerations' (an MSE
    head has no basis)."""
    return self.head == "mdn" and self.mdn_basis != "features"


@dataclasses.dataclass(frozen=True)
class OptimConfig:
  name: str = _field("adam", "optimizer", choices=("adam", "adamw", "amsgrad"))
  lr: float = _field(1e-3, "peak learning rate", minimum=0.0)
  b1: float = _field(0.9, "Adam beta1", minimum=0.0, below=1.0)
  b2: float = _field(0.999, "Adam beta2", minimum=0.0, below=1.0)
  weight_decay: float = _field(0.0, "decoupled weight decay (adamw)", minimum=0.0)
  clip_norm: float = _field(10.0, "clip gradients by global norm (0 = off)", minimum=0.0)
  schedule: str = _field("constant", "learning-rate schedule", choices=("constant", "warmup_cosine"))
  warmup_steps: int = _field(0, "linear warm-up steps (warmup_cosine)", minimum=0)
  final_lr_ratio: float = _field(0.1, "final lr / peak lr (warmup_cosine)", minimum=0.0)


@dataclasses.dataclass(frozen=True)
class TrainConfig:
  batch_size: int = _field(50, "windows per step (global, over all devices)", minimum=1)
  batch_parts: int = _field(
    1,
    "compute each batch as this many equal shares side by side, one thread each, then one update (rnn family)",
    minimum=1,
    more=(
      "On a CPU one program runs a time loop's small kernels one after another on one core; shares in threads "
      "run their loops on a core each. 2 on 2 cores: the LSTM step 11-20% less time (benchmarks.shipped), the "
      "quick start's 11-12%. The same loss in exact arithmetic, not in its last bits: each share draws its own "
      "noise and dropout. Must divide train.batch_size; not with parallel.data_parallel. Seeds trained as one "
      "vectorized program compute each point's shares one after another inside it (each share's own cut, "
      "noise and dropout, as in threads)."
    ),
    below=65,  # a share a core: more shares than cores gain nothing, and 100,000 made LLVM abort
  )
  num_steps: int = _field(1000, "total optimizer steps", minimum=0, resumable=True, below=2**31)
  seed: int = _field(0, "seed of parameters, batches, dropout and noise", minimum=0, below=2**32)
  checkpoint_every: int = _field(500, "steps between checkpoints", minimum=1)
  keep_checkpoints: int = _field(3, "latest checkpoints kept (the best by val loss is kept too)", minimum=1)
  eval_every: int = _field(250, "steps between validation passes (0 = only at the end)", minimum=0, resumable=True)
  epochs: float = _field(
    0.0,
    "training length in passes over the training frames (windows of data.seq_length); 0 = train.num_steps",
    minimum=0.0,
    resumable=True,
    more=(
      "Sets `train.num_steps` to epochs x training frames / (batch_size x seq_length), so a run's length "
      "follows its data: training says how many steps that is."
    ),
  )
  patience: int = _field(
    0,
    "end training after this many validation passes without a lower validation loss (0 = train to the end)",
    minimum=0,
    resumable=True,
    more="Needs `train.eval_every` > 0 and held-out takes. The sample and calibration of the end follow as usual.",
  )
  log_every: int = _field(50, "steps between log lines / metrics.jsonl rows", minimum=1, resumable=True)
  figure_every: int = _field(0, "steps between sample figures in TensorBoard (0 = off)", minimum=0, resumable=True)
  input_noise: float = _field(
    0.0, "std of Gaussian noise on inputs (normalized units), against exposure bias", minimum=0.0
  )
  val_windows: int = _field(64, "most validation windows evaluated", minimum=1)
  keep: str = _field(
    "last",
    "the checkpoint sample, eval, calibrate and live use by default: the 'last', or the 'best' by validation loss",
    more=(
      "`--checkpoint kept` (the default of those commands) follows it. A small dataset over-fits late, so "
      "'best' keeps the lowest held-out loss; with nothing held out it is the last."
    ),
    choices=("last", "best"),
    resumable=True,
  )
  calibrate: bool = _field(
    False,
    "after training, choose the sampling settings on the training takes (`chorjax calibrate`)",
    more=(
      "It chooses noise_smoothing, sigma_temperature, persistence, crossfade and foot_lock, and the end "
      "sample is drawn with them."
    ),
    resumable=True,
  )
  feedback: str = _field(
    "none",
    "feed the model's own outputs back in training: 'auto' (auto-conditioning), 'scheduled' or 'none'",
    more=(
      "Against exposure bias: 'auto' (Zhou et al. 2018) feeds ground_truth_frames real frames, then "
      "condition_frames own ones, repeating; 'scheduled' makes each frame the model's own with probability "
      "feedback_max x the schedule; 'none' is teacher forcing only."
    ),
    choices=("none", "auto", "scheduled"),
  )
  ground_truth_frames: int = _field(5, "auto-conditioning: real input frames per cycle", minimum=1)
  condition_frames: int = _field(5, "auto-conditioning: own output frames per cycle", minimum=1)
  feedback_max: float = _field(0.5, "scheduled sampling: the final probability of feeding an own frame", minimum=0.0)
  feedback_warmup: int = _field(0, "steps of teacher forcing before any feedback", minimum=0)
  feedback_ramp: int = _field(
    0, "steps over which feedback ramps linearly from none to full after the warm-up (0 = at once)", minimum=0
  )
  feedback_draw: str = _field(
    "sample",
    "what is fed back: a draw from the MDN at the run's sample temperatures (what generation feeds itself) "
    "or the mixture mean; always without gradient through it",
    choices=("sample", "mean"),
  )


@dataclasses.dataclass(frozen=True)
class _SampleWhat:
  frames: int = _field(600, "frames written by the sample at the end of training", minimum=1, resumable=True)
  num: int = _field(1, "dancers sampled in parallel", minimum=1, resumable=True)
  motion: int = _field(0, "motion id that conditions the sample")


@dataclasses.dataclass(frozen=True)
class SampleConfig(ControlFields, _SampleWhat):
  """``[sample]``: what is sampled, and the sampling controls (declared in ``chorjax.sampling.table``)."""

  seed: int = _field(0, "sampling seed", resumable=True, minimum=0, below=2**32)


@dataclasses.dataclass(frozen=True)
class LogConfig:
  tensorboard: bool = _field(True, "write tensorboardX event files into the workdir", resumable=True)
  progress: str = _field(
    "auto",
    "progress display: auto = a bar on a terminal, one line rewritten in place in Jupyter, lines otherwise",
    choices=("auto", "bar", "lines", "none"),
    resumable=True,
  )


@dataclasses.dataclass(frozen=True)
class ParallelConfig:
  data_parallel: bool = _field(False, "shard every batch over a 'data' mesh axis of all devices", resumable=True)
  num_devices: int = _field(0, "devices in the mesh (0 = all devices of all processes)", minimum=0, resumable=True)
  distributed: bool = _field(False, "call jax.distributed.initialize (multi-host / multi-process)", resumable=True)
  coordinator_address: str = _field(
    "", "HOST:PORT of process 0 ('' = detect from the cluster environment)", resumable=True
  )
  num_processes: int = _field(0, "processes in the job (0 = detect from the environment)", minimum=0, resumable=True)
  process_id: int = _field(-1, "this process's index (-1 = detect from the environment)", minimum=-1, resumable=True)


_BASE_SECTIONS = {
  "data": DataConfig,
  "model": ModelConfig,
  "optim": OptimConfig,
  "train": TrainConfig,
  "sample": SampleConfig,
  "log": LogConfig,
  "parallel": ParallelConfig,
}


def section_classes() -> dict[str, type]:
  """Every section's dataclass in schema order: the model families' own sections (``[gan]``, ...: each
  family's ``section``) right after ``[model]``."""
  base = list(_BASE_SECTIONS.items())
  return dict([*base[:2], *family_sections().items(), *base[2:]])


@dataclasses.dataclass(frozen=True)
class Config:
  """A run's configuration: a section per attribute (``cfg.train.batch_size``); a model family's own section
  (``cfg.gan``) is read the same way, from ``families`` (each family's defaults where not given)."""

  data: DataConfig = dataclasses.field(default_factory=DataConfig)
  model: ModelConfig = dataclasses.field(default_factory=ModelConfig)
  optim: OptimConfig = dataclasses.field(default_factory=OptimConfig)
  train: TrainConfig = dataclasses.field(default_factory=TrainConfig)
  sample: SampleConfig = dataclasses.field(default_factory=SampleConfig)
  log: LogConfig = dataclasses.field(default_factory=LogConfig)
  parallel: ParallelConfig = dataclasses.field(default_factory=ParallelConfig)
  name: str = "default"
  families: tuple = ()  # ((section, its dataclass instance), ...) of the model families' sections

  def __getattr__(self, name: str) -> Any:  # only for names that are no field: a family's section
    given = dict(self.__dict__.get("families", ()))
    if name in given:
      return given[name]
    cls = None if name.startswith("__") else family_sections().get(name)
    if cls is None:
      raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
    return cls()

  def to_dict(self) -> dict:
    d = {s: dataclasses.asdict(getattr(self, s)) for s in section_classes()} | {"name": self.name}
    return json.loads(json.dumps(d))  # tuples -> lists, a plain JSON tree

  def model_sections(self) -> tuple:
    """The sections that shape a model and its parameters (a checkpoint restored under others is checked
    leaf by leaf): ``[model]`` and the families' own."""
    return (self.model, *(getattr(self, s) for s in family_sections()))


def _config(sections: dict[str, dict], name: str) -> Config:
  """A Config of checked ``{section: {key: value}}`` (what a file or a saved dict gave)."""
  families = tuple((s, cls(**sections[s])) for s, cls in family_sections().items())
  return Config(**{s: cls(**sections[s]) for s, cls in _BASE_SECTIONS.items()}, name=name, families=families)


def key_docs(prefix: str = "", registered: bool = True) -> list[dict]:
  """Every config key under ``prefix`` (a section, ``sample``, or a key, ``sample.pace``), in schema order:
  ``{key, default, help, more, choices, minimum, below}``. A prefix that names nothing is a UserError."""
  rows = []
  for section, cls in section_classes().items():
    defaults = cls()
    for f in dataclasses.fields(cls):
      key = f"{section}.{f.name}"
      if key == prefix or key.startswith(prefix.rstrip(".") + ".") or not prefix:
        meta = f.metadata
        rows.append(
          {
            "key": key,
            "default": getattr(defaults, f.name),
            "help": meta["help"],
            "more": meta.get("more"),
            "choices": field_choices(meta, registered),
            "minimum": meta.get("minimum"),
            "below": meta.get("below"),
          }
        )
  if not rows:
    raise UserError(f"{prefix!r}: no such config key or section" + suggest(prefix, [*section_classes(), *valid_keys()]))
  return rows


def reference_markdown() -> str:
  """Every config key as the docs' reference page (``docs/config.md``): a table a section, each key's
  default, help with its range, and the notes of ``more``."""
  lines = ["# Config reference", "", "Generated from the config fields (`chorjax config keys --markdown`).", ""]
  section = None
  for row in key_docs(registered=False):  # the families chorjax ships, whatever this process registered
    name = row["key"].split(".")[0]
    if name != section:
      lines += [""] if section else []
      section = name
      lines += [f"## [{name}]", "", "| key | default | what it does |", "| --- | --- | --- |"]
    text = key_help(row) + (f"<br>*More:* {row['more']}" if row["more"] else "")
    cells = (f"`{row['key']}`", f"`{toml_value(row['default'])}`", text)
    lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
  return "\n".join(lines) + "\n"


def key_help(key: str | dict) -> str:
  """The help of one config key (or of a row of :func:`key_docs`), with its range or choices (what a flag
  that sets it says)."""
  row = key_docs(key)[0] if isinstance(key, str) else key
  bounds = []
  if row["choices"]:
    bounds.append("one of " + ", ".join(map(str, row["choices"])))
  if row["minimum"] is not None:
    bounds.append(f">= {row['minimum']:g}")
  if row["below"] is not None:
    bounds.append(f"< {row['below']:g}")
  return row["help"] + (f" [{', '.join(bounds)}]" if bounds else "")


def valid_keys() -> list[str]:
  return [f"{s}.{f.name}" for s, cls in section_classes().items() for f in dataclasses.fields(cls)]


def resumable_keys() -> list[str]:
  """Dotted keys that may change when a run is continued without --force (a field flag in the schema)."""
  return [
    f"{s}.{f.name}" for s, cls in section_classes().items() for f in dataclasses.fields(cls) if f.metadata["resumable"]
  ]


def suggest(key: str, options: Sequence[str]) -> str:
  """ "; did you mean 'x'?" for the closest of ``options``, or ""."""
  close = difflib.get_close_matches(key, options, n=1, cutoff=0.5)
  return f"; did you mean {close[0]!r}?" if close else ""


def check_sample_control(name: str, value, where: str):
  """``value`` checked as ``[sample] name`` is in a config file (type, range, finite); ``where`` names
  its source in the error (e.g. the command-line flag)."""
  field = {f.name: f for f in dataclasses.fields(SampleConfig)}[name]
  return _check_value(where, f"sample.{name}", field, value)


def _short(value: Any) -> str:
  """``repr(value)``, cut to 60 characters: an error line names the value, it does not reprint a huge one."""
  text = repr(value)
  return text if len(text) <= 60 else text[:57] + "..."


def _check_value(where: str, key: str, field: dataclasses.Field, value: Any):
  """Returns ``value`` converted to the field's type, or raises a UserError naming ``key``."""
  hint = typing.get_type_hints(section_classes()[key.split(".")[0]])[field.name]
  meta = field.metadata
  if hint is bool:
    ok = isinstance(value, bool)
  elif hint is int:
    ok = isinstance(value, int) and not isinstance(value, bool)
  elif hint is float:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    value = float(value) if ok else value
  elif hint is str:
    ok = isinstance(value, str)
  elif hint is tuple:
    ok = isinstance(value, (list, tuple)) and all(isinstance(v, (str, int)) and not isinstance(v, bool) for v in value)
    value = tuple(value) if ok else value
  else:  # pragma: no cover - schema error
    raise TypeError(hint)
  if not ok:
    tname = "list" if hint is tuple else hint.__name__
    raise UserError(f"{where}: key {key!r}: expected {tname}, got {type(value).__name__} {_short(value)}")
  if hint is float and not math.isfinite(value):
    raise UserError(f"{where}: key {key!r}: {value!r} is not a finite number")
  items = value if isinstance(value, tuple) else (value,)  # a list (a tuple by now): each element
  choices = field_choices(meta)
  for item in items:
    if choices and item not in choices:
      raise UserError(
        f"{where}: key {key!r}: {item!r} is not one of {', '.join(map(repr, choices))}"
        + suggest(str(item), [str(c) for c in choices])
      )
  if meta.get("minimum") is not None and value < meta["minimum"]:
    raise UserError(f"{where}: key {key!r}: {value!r} is below the minimum {meta['minimum']}")
  if meta.get("below") is not None and not value < meta["below"]:
    raise UserError(f"{where}: key {key!r}: {value!r} must be below {meta['below']}")
  return value


def _line_of(text: str, section: str, key: str) -> int | None:
  """The line of ``key`` inside ``[section]`` (tomllib does not report positions)."""
  current = None
  for i, line in enumerate(text.splitlines(), start=1):
    m = re.match(r"\s*\[([^\]]+)\]\s*(#.*)?$", line)
    if m:
      current = m.group(1).strip()
      continue
    if re.match(rf"\s*{re.escape(key)}\s*=", line) and current == section:
      return i
    if re.match(rf"\s*{re.escape(section)}\.{re.escape(key)}\s*=", line) and current is None:
      return i
  return None


def _apply(sections: dict[str, dict], tree: dict, where_of) -> None:
  """Checks a ``{section: {key: value}}`` tree and merges it into ``sections``."""
  for section, body in tree.items():
    if section == "name":
      continue
    if section not in section_classes():
      raise UserError(
        f"{where_of(section, None)}: unknown section {section!r}" + suggest(section, list(section_classes()))
      )
    if not isinstance(body, dict):
      raise UserError(f"{where_of(section, None)}: {section!r} must be a table ([{section}])")
    fields = {f.name: f for f in dataclasses.fields(section_classes()[section])}
    for key, value in body.items():
      dotted = f"{section}.{key}"
      if key not in fields:
        raise UserError(f"{where_of(section, key)}: unknown key {dotted!r}" + suggest(dotted, valid_keys()))
      sections[section][key] = _check_value(where_of(section, key), dotted, fields[key], value)


def parse_override(text: str) -> tuple[str, Any]:
  """``'optim.lr=3e-4'`` -> ``('optim.lr', 0.0003)``; values are TOML, else bare strings."""
  if "=" not in text:
    raise UserError(f"override {text[:80]!r}: expected KEY=VALUE, e.g. model.cell=gru")
  key, raw = (s.strip() for s in text.split("=", 1))
  try:
    value = load_toml(f"v = {raw}")["v"]
  except tomllib.TOMLDecodeError:
    value = raw
  return key, value


MAX_BASES = 16  # configs a file may stand on, one on another (base = "...")


def _apply_file(sections: dict[str, dict], path: Path, below: tuple = ()) -> str:
  """Merges the config file ``path`` into ``sections``: first the file its top-level ``base = "FILE"`` names
  (a path relative to it; that file's own base first, and so on), then its own keys. Returns its name (its
  ``name``, else its file name's stem)."""
  try:
    text = read_text(path, "config")  # a byte-order mark some editors write is not TOML; pipes refused
  except OSError as e:
    raise UserError(f"{path}: cannot read ({type(e).__name__})") from None
  try:
    tree = load_toml(text)
  except tomllib.TOMLDecodeError as e:
    raise UserError(f"{path}: invalid TOML: {e}") from None

  def where_of(section, key):
    line = _line_of(text, section, key) if key else _line_of_section(text, section)
    return f"{path}:{line}" if line else str(path)

  base = tree.pop("base", None)
  if base is not None:
    where = f"{path}:{_line_of_section(text, 'base') or 1}"
    if not isinstance(base, str) or not base:
      raise UserError(f"{where}: key 'base': expected the path of another config file")
    below = (*below, path.resolve())
    target = path.parent / base
    if target.resolve() in below or len(below) > MAX_BASES:
      raise UserError(f"{where}: base {base!r} leads back to itself ({' -> '.join(p.name for p in below)})")
    if not target.is_file():
      raise UserError(f"{where}: base {base!r}: no such file beside it ({target})")
    _apply_file(sections, target, below)
  _apply(sections, tree, where_of)
  name = tree.get("name", path.stem)
  if not isinstance(name, str):
    raise UserError(f"{path}: key 'name': expected str")
  return name


def load_config(path: str | Path | Config | dict | None = None, overrides: Sequence[str] = ()) -> Config:
  """Loads a TOML config file (or the defaults, a loaded ``Config``, or a ``{section: {key: value}}`` dict as
  a file's tables would be) and applies dotted ``KEY=VALUE`` overrides.

  Raises:
    UserError: for a missing or malformed file, an unknown section or key, a wrong type, or a
      value out of range; the message names the file (and line) or the override.
  """
  sections: dict[str, dict] = {s: {} for s in section_classes()}
  name = "default"
  if isinstance(path, Config):  # chorjax.train(config) from Python: the same overrides, the same checks
    _apply(sections, {k: v for k, v in path.to_dict().items() if k != "name"}, lambda s, k: "the given config")
    name = path.name
  elif isinstance(path, dict):  # chorjax.train({"model": {"cell": "gru"}}): checked as a file's tables are
    _apply(sections, path, lambda s, k: "the given dict")
    name = str(path.get("name", name))
  elif isinstance(path, str | Path):
    name = _apply_file(sections, Path(path))
  elif path is not None:
    raise UserError(f"config: expected a TOML file's path, a Config or a dict, got {type(path).__name__}")
  for item in overrides:
    key, value = parse_override(item)
    if key == "name":
      name = str(value)
      continue
    if "." not in key:
      raise UserError(f"override {item[:80]!r}: expected SECTION.KEY=VALUE" + suggest(key, valid_keys()))
    section, sub = key.split(".", 1)
    _apply(sections, {section: {sub: value}}, lambda s, k, item=item: f"override {item[:80]!r}")
  config = _config(sections, plain_name(name, "name"))
  check_combinations(config)
  check_training_size(config)
  return config


def check_combinations(config: Config) -> None:
  """Keys that make sense alone but not together, refused when a config is loaded (before any training;
  runs already saved with them still load: their sampling says so when asked)."""
  if not config.data.cache.strip():  # an empty path is the working directory: entries among the user's files
    raise UserError("key 'data.cache': empty; give auto, off, or a folder")
  parts, size = config.train.batch_parts, config.train.batch_size
  if parts > 1 and size % parts:
    raise UserError(f"key 'train.batch_parts': {parts} does not divide train.batch_size = {size}")
  family_of(config).check_keys(config)  # keys of another model family's
  if parts > 1 and config.parallel.data_parallel:
    raise UserError(
      "key 'train.batch_parts': not with parallel.data_parallel (the batch is shared over the devices already)"
    )
  rep = config.data.representation
  for key in ("foot_lock", "ground"):
    if getattr(config.sample, key) and rep != "canonical":
      raise UserError(
        f"key 'sample.{key}': needs data.representation = 'canonical' (here {rep!r}); set sample.{key}=false"
      )


FEATURES_GUESS = 256  # pose features per frame, more than any skeleton we read gives (mpii16 canonical: ~50)


def training_bytes(config: Config) -> float:
  """What one model's train step needs, estimated from the sizes alone (:func:`check_training_size`): the
  parameters with Adam's two moments, and the activations the step keeps for its backward pass, in float32."""
  m, t, d = config.model, config.train, config.data
  h, layers, inputs = m.hidden_size, m.num_layers, FEATURES_GUESS
  params = layers * 4 * h * (h + max(h, inputs)) + h * FEATURES_GUESS * (2 * m.num_mixtures + 1)
  components = m.num_mixtures if m.head == "mdn" else 1
  activations = t.batch_size * d.seq_length * (layers * h * 16 + components * FEATURES_GUESS * 6)
  return 4.0 * (3 * params + activations)


def check_training_size(config: Config, copies: int = 1) -> None:
  """A one-line ``UserError`` naming the keys when training would need more memory than this machine has,
  estimated from the sizes alone (before anything is allocated): the parameters with Adam's two moments,
  and the activations a step keeps for its backward pass (about 16 values per unit, layer and frame, and the
  head's: about 6 per feature and mixture component per frame, which rule small models); for ``copies``
  models trained together as one program (a list of seeds), all of them."""
  m, t, d = config.model, config.train, config.data
  together = f" x {copies:,} points trained together" if copies > 1 else ""
  check_memory(
    training_bytes(config) * copies,
    f"model.hidden_size={m.hidden_size}, model.num_layers={m.num_layers}, train.batch_size={t.batch_size}, "
    f"data.seq_length={d.seq_length}{together}",
  )
  # the sample written at the end of training (as Run.check_drawn counts a draw), before training starts
  check_draw(config.sample.frames * copies, FEATURES_GUESS // 4 + 48, f"sample.frames={config.sample.frames}")


def plain_name(name: str, what: str) -> str:
  """``name`` if it can be one folder's name (runs/<name>), else a one-line UserError: a name with ``/`` or
  ``..`` would write a run outside the runs folder."""
  if not name or name.startswith(".") or ".." in name or any(c in name for c in "/\\\0") or len(name) > 200:
    raise UserError(f"{what} {name!r}: must be a plain file name (no / or \\, no .., not starting with .)")
  return name


def _line_of_section(text: str, section: str) -> int | None:
  for i, line in enumerate(text.splitlines(), start=1):
    if re.match(rf"\s*\[{re.escape(section)}\]", line) or re.match(rf"\s*{re.escape(section)}\s*=", line):
      return i
  return None


def config_from_dict(d: dict) -> Config:
  """Rebuilds a Config saved with ``to_dict`` (checked like a file)."""
  sections: dict[str, dict] = {s: {} for s in section_classes()}
  _apply(sections, {k: v for k, v in d.items() if k != "name"}, lambda s, k: "saved config")
  return _config(sections, d.get("name", "default"))


def config_diff(a: Config, b: Config, ignore: Sequence[str] = ()) -> list[str]:
  """Dotted keys whose values differ between two configs."""
  da, db = a.to_dict(), b.to_dict()
  out = []
  for s in section_classes():
    for k in da[s]:
      if da[s][k] != db[s][k] and f"{s}.{k}" not in ignore:
        out.append(f"{s}.{k}: {da[s][k]!r} -> {db[s][k]!r}")
  return out


def toml_value(v) -> str:
  """A config value as TOML writes it."""
  if isinstance(v, bool):
    return "true" if v else "false"
  if isinstance(v, str):
    return json.dumps(v)
  if isinstance(v, (list, tuple)):
    return "[" + ", ".join(toml_value(x) for x in v) + "]"
  return repr(v)


def to_toml(cfg: Config) -> str:
  """The resolved config as TOML text (what ``chorjax config show`` prints)."""
  fmt = toml_value
  lines = [f"name = {fmt(cfg.name)}"]
  for s, body in cfg.to_dict().items():
    if s == "name":
      continue
    lines.append(f"\n[{s}]")
    lines += [f"{k} = {fmt(v)}" for k, v in body.items()]
  return "\n".join(lines) + "\n"
