"""The run configuration's own sections, ``[data]`` to ``[parallel]``: each key's default, help and checks
(``fields.config_field``), from which ``chorjax.config`` reads and checks files and ``chorjax config keys`` and
``docs/config.md`` are made. A model family's section is its family's (``Family.section``); ``[sample]``'s
controls are ``chorjax.sampling.table``'s."""

from __future__ import annotations

import dataclasses

from chorjax.fields import config_field as _field
from chorjax.registry import names as family_names
from chorjax.sampling.table import ControlFields


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
  keep_side: bool = _field(
    False,
    "no mirrored copies of training takes that favour one side (a twin joint 1.5x as fast as its twin)",
    more=(
      "Mirrored, a dancer who leads with one foot is taught both sides and dances them alike; kept to its side, "
      "CMU 131 travels further, its poses nearer its held-out take (experiments/draw). Training names the joint."
    ),
  )
  loop: float = _field(
    0.0,
    "training takes shorter than this many seconds play back to back up to it: a short action is done again (0: off)",
    more=(
      "A library's short takes (a raised hand, a run) start and end standing: trained as they are, the dancer "
      "learns to stand once the action is done; looped, it learns to do it again. Takes shorter than one window "
      "are then kept for training; held-out ones that short are left out of validation."
    ),
    minimum=0.0,
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
  mdn_radius: float = _field(
    1.0,
    "the carried residuals' autoregression keeps its roots within this radius: a deviation fades within about "
    "1 / (1 - radius) frames (1 = any stationary one)",
    more=(
      "Each lag's coefficient is scaled by radius^lag, which scales every root of the autoregression by the "
      "radius: what the residuals keep doing fades, and the means have to carry the motion over longer times. "
      "With `model.mdn_carry = 'smooth'` and 3 lags the polynomial at -1 may then fall a little under 1 (to "
      "0.94 at radius 0.5)."
    ),
    minimum=0.0,
    maximum=1.0,
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
