"""chorjax as a Python library: train, sample, score and watch from a notebook or a script.

    import chorjax
    run = chorjax.train("configs/quickstart.toml")       # or chorjax.load_run("runs/quickstart")
    dance = run.sample(frames=600, seed=0)                # the draw `chorjax sample` makes
    dance.show(chorjax.read_motion("take.bvh"))           # the HTML player, inline in Jupyter
    chorjax.score(dance, "cmu94")                         # the keys of `chorjax metrics`
    dance.write("dance.bvh")                              # CSV, NPZ, BVH (onto a character too), glTF, HTML

The command line is a thin layer over these functions: the same checks, the same files on disk, and the
same one-line messages, raised here as :class:`chorjax.UserError`.
"""

from __future__ import annotations

import dataclasses
import html
import io
from collections.abc import Sequence
from pathlib import Path
from typing import Any  # noqa: F401  (the inherited fields' annotations name these: the API docs resolve them here)

import numpy as np

from chorjax.compare import compare_to  # noqa: F401
from chorjax.config import (  # noqa: F401
  Config,
  key_docs,
  key_help,
  load_config,
  parse_override,
  reference_markdown,
  to_toml,
  toml_value,
)
from chorjax.data import formats  # noqa: F401  (the formats each command reads, writes and draws)
from chorjax.data import motion as _motion
from chorjax.data.dataset import read_motions, read_takes
from chorjax.data.features import Features  # noqa: F401
from chorjax.data.formats import suffixes, written_paths
from chorjax.data.motion import Skeleton  # noqa: F401
from chorjax.errors import (
  Interrupted,  # noqa: F401
  UserError,
  as_path,
  atomic_write,
  check_output,
  refuse_existing,
)
from chorjax.evaluation.evaluate import evaluate_to  # noqa: F401
from chorjax.evaluation.reports import check_report, metric_keys, metric_lines, takes_table  # noqa: F401
from chorjax.evaluation.scoring import (
  score_motions,
  score_to,  # noqa: F401
)
from chorjax.export.blender import write_blender_addon  # noqa: F401
from chorjax.export.dancer import (
  export_onnx,
  write_onnx,  # noqa: F401
)
from chorjax.export.web import write_web  # noqa: F401
from chorjax.io.convert import convert  # noqa: F401
from chorjax.io.output import write_motions
from chorjax.live.server import run_live  # noqa: F401
from chorjax.render.files import plot_file, render  # noqa: F401
from chorjax.render.html import player_html
from chorjax.render.plot import strip_figure
from chorjax.run import Run as _Run
from chorjax.run import load_run as _load_run
from chorjax.runtime import keep_compiled_programs, keep_freed_memory  # noqa: F401
from chorjax.sample import sample_dancers, write_inbetween, write_sample  # noqa: F401

# What every command does, as functions (the command line calls these and prints what they return).
from chorjax.sampling.calibrate import (  # noqa: F401
  CALIBRATION_DANCERS,
  CALIBRATION_FRAMES,
  CARRIED_FRAMES,
  LABELLED_DANCERS,
  calibrate_run,
)
from chorjax.sampling.controls import Controls  # noqa: F401
from chorjax.sampling.table import CALIBRATED, FLAGGED, PLAIN, RECORDS, Given  # noqa: F401
from chorjax.sampling.table import SWITCHES as CONTROL_SWITCHES  # noqa: F401
from chorjax.sweeps import SWEEP_DESCRIPTION, SWEEP_FORMAT, run_sweep, train_command  # noqa: F401
from chorjax.training.driver import default_workdir, train_and_evaluate
from chorjax.training.end_of_run import standard

__all__ = ["Motion", "Player", "Run", "UserError", "load_dataset", "load_run", "read_motion", "score", "train"]


def _check_writable(positions, path) -> None:
  """A UserError unless ``positions`` hold at least one frame, every number finite: no file of any format says
  what a NaN joint or an empty dance is (the writers failed with a traceback or wrote NaN silently)."""
  pos = np.asarray(positions)
  if pos.shape[0] == 0:
    raise UserError(f"{path}: the motion has no frames; nothing written")
  bad = ~np.isfinite(pos.reshape(pos.shape[0], -1)).all(-1)
  if bad.any():
    raise UserError(f"{path}: frame {int(np.argmax(bad))} holds NaN or infinity; nothing written")


@dataclasses.dataclass(frozen=True, repr=False)  # the base's one-line repr
class Motion(_motion.Motion):
  """One take or one generated dancer: ``positions [T, J, 3]``, ``fps``, ``skeleton``, ``up_axis`` ...
  (see ``chorjax.data.motion.Motion``), with a way to write, watch and draw it."""

  @classmethod
  def of(cls, motion: _motion.Motion) -> Motion:
    """``motion`` as this class (the readers and samplers return the plain data class)."""
    return _recast(cls, motion)

  def write(self, path, skeleton=None, *, force: bool = False) -> Path:
    """Writes the motion as ``path``'s suffix says: ``.csv``, ``.npz``, ``.bvh`` (with ``skeleton``, a
    character BVH: the dance on its hierarchy, as ``chorjax sample --skeleton``), ``.glb`` (binary glTF: the
    skeleton's nodes and their animation) or ``.html`` (the player).
    An existing file is not replaced unless ``force``."""
    path, suffix = check_output(path, suffixes("write"))
    if "\x00" in str(path):
      raise UserError(f"{path!r}: a file name cannot hold a NUL character")
    refuse_existing(written_paths(path, 1, self.skeleton), force, how="force=True")  # a sidecar is the user's too
    _check_writable(self.positions, path)
    if skeleton is not None and suffix != ".bvh":
      raise UserError(f"{path}: a character skeleton is for .bvh output")
    title = self.name or "chorjax"
    try:
      return write_motions(path, [self], settings={"name": self.name}, character=skeleton, title=title)[0]
    except OSError as e:  # a folder that is not there or not writable, a folder named like the file: one line
      raise UserError(f"{path}: cannot be written ({e.strerror or e})") from None

  def show(self, *others: _motion.Motion, title: str | None = None) -> Player:
    """The HTML player with this motion and ``others`` side by side; shown inline by Jupyter (and kept in
    a notebook's HTML export), or ``.html`` for the page."""
    motions = [self, *others]
    for m in others:
      if not isinstance(m, _motion.Motion):
        raise UserError(f"show: expected motions (chorjax.Motion), got {type(m).__name__}")
    if title is not None and not isinstance(title, str):
      raise UserError(f"show: title must be text, got {type(title).__name__}")
    return Player(player_html(motions, title or " | ".join(m.name or "motion" for m in motions)))

  def strip(self, every: int = 6, poses: int = 12):
    """The filmstrip figure (matplotlib): ``poses`` figures ``every`` frames apart at the start, middle and
    end, as ``chorjax render --strip`` draws it."""
    fig = strip_figure(self, every, poses)

    def png() -> bytes:
      buffer = io.BytesIO()
      fig.savefig(buffer, format="png", dpi=80)
      return buffer.getvalue()

    fig._repr_png_ = png  # type: ignore[attr-defined]  # Jupyter shows it inline, whatever its plotting backend
    return fig


@dataclasses.dataclass(frozen=True)
class Player:
  """A self-contained player page. Jupyter shows it inline (``_repr_html_``: an iframe holding the page,
  so its script runs in JupyterLab, the classic notebook and an exported HTML file alike)."""

  html: str
  height: int = 480

  def __repr__(self) -> str:
    return f"Player({len(self.html) / 1024:,.0f} KiB page, {self.height} px high)"

  def _repr_html_(self) -> str:
    return (
      f'<iframe srcdoc="{html.escape(self.html, quote=True)}" style="width:100%;height:{self.height}px;border:0" '
      'sandbox="allow-scripts"></iframe>'
    )

  def save(self, path) -> Path:
    return atomic_write(path, lambda p: p.write_text(self.html, encoding="utf-8"))


@dataclasses.dataclass(frozen=True, repr=False)  # the base's one-line repr
class Run(_Run):
  """A trained run (see ``chorjax.run.Run``: ``config``, ``features``, ``id_map``, ``step`` ...) that can dance."""

  def sample(
    self,
    frames: int = 600,
    num: int = 1,
    seed: int = 0,
    prime: str | None = None,
    motion: int | None = None,
    mix: str | None = None,
    **controls,
  ) -> Motion | list[Motion]:
    """New dance: ``num`` dancers of ``frames`` frames, the draw ``chorjax sample`` makes with the same
    arguments. ``prime``: ``FILE[:START:LEN]``, a phrase to continue; ``motion``: the take id to dance
    (default 0), or ``mix``: ``"ID:W,ID:W"``; ``controls``: sampling controls (``pi_temperature``,
    ``noise_smoothing`` ...; unset: the run's calibration, then its ``[sample]``). One dancer is returned
    as a :class:`Motion`, several as a list."""
    pos, _ = sample_dancers(self, frames, num, seed, prime, motion, mix, controls)
    f = self.features
    name = f"{Path(self.workdir).name} seed {seed}"
    out = [
      Motion(p, self.fps, f.skeleton, f.up_axis, "data", name=name if num == 1 else f"{name} #{k}")
      for k, p in enumerate(pos)
    ]
    return out[0] if num == 1 else out

  def export(self, path, *, batch: int = 1, force: bool = False, **controls) -> list[Path]:
    """The dancer as an ONNX model at ``path`` (``.onnx``) with its JSON sidecar, as ``chorjax export``:
    ``batch`` dancers a call, ``controls`` the sampling controls (unset: the run's own). Returns the paths
    written (:class:`chorjax.export.dancer.OnnxDancer` runs it)."""
    return export_onnx(self, path, batch=batch, controls=controls, force=force)


def load_run(workdir, checkpoint: str | int = "kept") -> Run:
  """The trained run in ``workdir`` at ``checkpoint`` (``kept``: what its ``train.keep`` names; ``latest``,
  ``best`` or a step number)."""
  return _recast(Run, _load_run(workdir, checkpoint))


def _recast(cls, obj):
  """``obj`` (a dataclass instance of ``cls``'s base) as ``cls``, field for field."""
  return obj if isinstance(obj, cls) else cls(**{f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)})


def train(config, workdir=None, overrides: Sequence[str] | None = None, *, force: bool = False) -> Run:
  """Trains ``config`` (a TOML path, a loaded ``chorjax.config.Config`` or a ``{section: {key: value}}``
  dict; ``overrides``: ``"key=value"`` strings) in ``workdir`` (default ``runs/<name>``), resuming from its
  latest checkpoint as ``chorjax train`` does, and returns the run at the checkpoint it keeps."""
  cfg = load_config(config, list(overrides or []))
  workdir = Path(workdir) if workdir is not None else default_workdir(cfg)
  train_and_evaluate(cfg, workdir, force=force, finish=standard(cfg))
  return load_run(workdir)


def read_motion(path) -> Motion | list[Motion]:
  """A motion file in any format the command line reads (CSV, BVH, ASF/AMC, C3D, NPZ): one take, or the
  dancers of a sample ``.npz`` (a list when it holds several)."""
  path = as_path(path, "read_motion")
  if not path.is_file():
    raise UserError(f"{path}: no such file")
  motions = [Motion.of(m) for m in read_motions(path)]
  return motions[0] if len(motions) == 1 else motions


def load_dataset(name_or_dir) -> list[Motion]:
  """Every take of a bundled dataset (``cmu94``), a folder or a file, as training reads them."""
  return [Motion.of(m) for m in read_takes([str(name_or_dir)])]


def score(motions, data, **kw) -> dict:
  """The metrics of ``chorjax metrics`` (same keys, same ruler) for ``motions`` (a Motion, a list of them,
  or file paths) against the real takes of ``data`` (a bundled name, folder or file, or a list of them;
  or Motions). ``kw``: ``window``, ``splits``, ``seed``."""
  as_list = lambda x: list(x) if isinstance(x, list | tuple) else [x]
  read = lambda x: [x] if isinstance(x, _motion.Motion) else load_dataset(x)
  return score_motions(
    [m for x in as_list(motions) for m in read(x)], [m for x in as_list(data) for m in read(x)], **kw
  )
