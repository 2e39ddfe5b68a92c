"""``chorjax export``: a trained dancer as an ONNX model that any host (onnxruntime in Python, C#, C++ or the
browser; Unity's Sentis; TouchDesigner) runs frame by frame, with a JSON sidecar that says how.

The graph is one frame of the run's draw (its family's ``frame_program``; for the recurrent family
``generation.frame_step``, the code every frame of ``chorjax sample`` runs): the state in, the next frame
and the new state out, with the run's sampling controls inside (temperatures, smoothed noise,
persistence, crossfade, the training range, the pace governor, the scale ceiling). The host owns the
random stream: each frame takes standard Gumbel noise ``[B, K]`` (which component is drawn) and standard
normal noise ``[B, N]``; given the numbers ``chorjax sample --seed S`` draws (:func:`sample_numbers`), its
frames are ``chorjax sample``'s. A GAN's generator runs the same way, its noise vector in ``normal`` on a
dancer's first frame.

The contract (also in the sidecar's ``inputs``, ``outputs`` and ``state``):

* ``weights [B, M]``: the motion the dancer is conditioned on, one-hot over the run's motions or a blend;
* ``start [B]``: 1 for a dancer's first frame (its state is then the weights' initial state), else 0;
* ``gumbel [B, K]``, ``normal [B, N]``: this frame's random numbers;
* ``state.*``: the state the previous call returned (zeros before the first frame);
* out ``frame [B, D]``: the next frame's normalized features; ``positions [B, J, 3]``: its joints in data space,
  decoded in the graph (``Features.decode_frame``: rigid bones where the run decodes so; grounding and foot
  lock look at every frame and are left to the host); ``state.*`` for the next call (``state.place``: where
  the dancer stands and faces).

:class:`OnnxDancer` also decodes frames as ``chorjax sample`` does, grounded and locked feet included, from the
run's feature pipeline (the sidecar's ``features``).
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import jax
import numpy as np

from chorjax.data.features import Features
from chorjax.data.transforms import up_axis_matrix
from chorjax.errors import UserError, atomic_write, check_output, refuse_existing
from chorjax.run import load_run

SIDECAR_FORMAT = "chorjax-onnx-dancer"
SIDECAR_VERSION = 1


def sidecar_path(model_path) -> Path:
  """Where the sidecar of ``dancer.onnx`` lives: ``dancer.json`` beside it."""
  return Path(model_path).with_suffix(".json")


MAX_BATCH = 4096


def write_onnx(
  workdir, output, *, batch: int = 1, controls: dict | None = None, checkpoint="kept", force: bool = False
) -> list[Path]:
  """``chorjax export``: the run in ``workdir`` as an ONNX dancer (:func:`export_onnx`)."""
  return export_onnx(load_run(workdir, checkpoint), output, batch=batch, controls=controls, force=force)


def export_onnx(run, output, *, batch: int = 1, controls: dict | None = None, force: bool = False) -> list[Path]:
  """Writes ``run``'s one-frame draw to ``output`` (``.onnx``) and its sidecar beside it, for ``batch``
  dancers a call, with the sampling ``controls`` given (unset: the run's calibration, then its ``[sample]``).
  Everything that can be refused is refused before anything is written; an existing file is not replaced
  unless ``force``. Returns the paths written."""
  needs_onnx()
  out, _ = check_output(output, (".onnx",))
  if isinstance(batch, bool) or not isinstance(batch, int | np.integer) or not 1 <= batch <= MAX_BATCH:
    raise UserError(f"--batch {batch!r}: must be a whole number within 1-{MAX_BATCH}")
  side = sidecar_path(out)
  refuse_existing([out, side], force)
  for p in (out, side):  # --force replaces files, never a folder (the .onnx would be left without its sidecar)
    if p.is_dir():
      raise UserError(f"{p}: is a folder; the dancer and its sidecar are files: give another -o")
  run = run.serving("export")
  sampling = run.sampling(**(controls or {}))
  if sampling.greedy:
    raise UserError(f"{run.workdir}: sample.greedy is not exported (a host wanting the mean frame passes zero noise)")
  run = run.ranged(sampling)
  model, contract = _program(run, sampling, batch)
  try:  # strict JSON: a host's parser takes no bare NaN or Infinity
    text = json.dumps(_sidecar(run, sampling, batch, contract), indent=1, allow_nan=False)
  except ValueError:
    raise UserError(
      f"{run.workdir}: its saved meta holds a value that is no number (NaN or infinity, e.g. its fps)"
    ) from None
  atomic_write(out, lambda tmp: Path(tmp).write_bytes(model.SerializeToString()), overwrite=True)
  atomic_write(side, lambda tmp: Path(tmp).write_text(text), overwrite=True)
  return [out, side]


def needs_onnx() -> None:
  """A UserError naming the export extra unless onnx is installed (checked before any work)."""
  if importlib.util.find_spec("onnx") is None:
    raise UserError("chorjax export needs the export extra: pip install 'chorjax[export]'")


def _program(run, sampling, batch: int):
  """``(onnx model, contract)``: the family's frame program traced for ``batch`` dancers and translated."""
  from chorjax.export.onnx_graph import Unsupported, to_onnx  # the export extra's onnx: read only to export

  draw = sampling.draw(run.features)
  family = run.family
  program, args, inputs, outputs = family.frame_program(
    run.graphdef, run.params, run.features, draw, batch, run.num_motions
  )
  program, args, inputs, outputs = _with_positions(program, args, inputs, outputs, run.features, sampling)
  try:
    graph = to_onnx(program, args, inputs, outputs, doc=f"chorjax dancer: {run.workdir}")
  except Unsupported as e:
    raise UserError(f"{run.workdir}: {e}") from None
  example = jax_outputs(program, args)
  state_in = inputs[4:]
  contract = {
    "inputs": [_io(n, a) for n, a in zip(inputs, args, strict=True)],
    "outputs": [_io(n, a) for n, a in zip(outputs, example, strict=True)],
    "state": [{"input": i, "output": o} for i, o in zip(state_in, outputs[2:], strict=True)],
  }
  return graph, contract


def _with_positions(program, args, inputs, outputs, features, sampling):
  """The frame program with the frame's joint positions decoded in it (``Features.decode_frame``): a
  ``positions [B, J, 3]`` output after ``frame`` and the place it carries as one more state,
  ``state.place`` (zeros at a dancer's first frame)."""
  rigid = sampling.decoding()["rigid"]
  batch = args[0].shape[0]

  def decoded(*values):
    *given, place = values
    out = list(program(*given))
    positions, place = features.decode_frame(out[0], place * (1.0 - given[1])[:, None], rigid)
    return [out[0], positions, *out[1:], place]

  args = [*args, np.zeros((batch, 3), np.float32)]
  return decoded, args, [*inputs, "state.place"], [outputs[0], "positions", *outputs[1:], "state.place.next"]


def jax_outputs(program, args) -> list:
  """The shapes and dtypes of ``program(*args)``'s outputs (nothing computed)."""
  return list(jax.eval_shape(program, *args))


def _io(name: str, value) -> dict:
  return {"name": name, "shape": list(value.shape), "dtype": str(np.dtype(value.dtype))}


def _sidecar(run, sampling, batch: int, contract: dict) -> dict:
  f = run.features
  sk = f.skeleton
  shapes = {io["name"]: io["shape"] for io in [*contract["inputs"], *contract["outputs"]]}
  k, n, d = shapes["gumbel"][1], shapes["normal"][1], shapes["frame"][1]
  return {
    "format": SIDECAR_FORMAT,
    "version": SIDECAR_VERSION,
    "run": str(run.workdir),
    "checkpoint_step": run.step,
    "fps": run.fps,
    "batch": batch,
    "family": run.config.model.family,
    "dim": d,
    "num_mixtures": k,
    "normal_size": n,
    "motions": dict(sorted(run.id_map.items(), key=lambda kv: kv[1])),
    "skeleton": {
      "joint_names": list(sk.joint_names),
      "parents": list(sk.parents),
      "bone_lengths": None if f.lengths is None else np.asarray(f.lengths).tolist(),
      "up_axis": f.up_axis,
      "to_y_up": np.asarray(up_axis_matrix(f.up_axis)).tolist(),  # positions @ to_y_up.T: y up
    },
    "positions": "data-space joints [B, J, 3] decoded in the graph with the decoding's rigid bones; grounding and"
    " foot lock (decoding.ground, decoding.lock_feet) look at every frame and are left to the host",
    "controls": sampling.to_dict(),
    "decoding": sampling.decoding(),
    "random_numbers": {
      "gumbel": "standard Gumbel [B, K] each frame: -log(-log(u)), u uniform in (0, 1)",
      "normal": "standard normal [B, N] each frame (N: normal_size)",
      "chorjax": "chorjax sample --seed S draws the numbers chorjax.export.dancer.sample_numbers(run, S, frames) gives",
    },
    **contract,
    "features": f.to_dict(),
  }


def sample_numbers(run, seed: int, frames: int, batch: int = 1):
  """``(gumbel [T, B, K], normal [T, B, N])``: the random numbers each frame of ``chorjax sample --seed seed``
  (``batch`` dancers) is drawn with, as the run's exported graph takes them (``Family.frame_numbers``)."""
  gumbel, normal = run.family.frame_numbers(run.graphdef, run.params, jax.random.key(seed), frames, batch)
  return np.asarray(gumbel, np.float32), np.asarray(normal, np.float32)


class OnnxDancer:
  """The reference host of an exported dancer: onnxruntime in Python, following the sidecar's contract as any
  other host would. ``dance`` draws frames from given random numbers, and the graph's joint positions with
  them; ``positions`` decodes frames as ``chorjax sample`` does, grounding and foot lock included."""

  def __init__(self, path):
    try:
      import onnxruntime as ort  # the export extra: only the reference host runs it
    except ImportError:
      raise UserError("OnnxDancer needs onnxruntime (the export extra): pip install 'chorjax[export]'") from None

    self.path = Path(path)
    self.meta = json.loads(sidecar_path(self.path).read_text())
    if self.meta.get("format") != SIDECAR_FORMAT:
      raise UserError(f"{sidecar_path(self.path)}: not a chorjax dancer's sidecar")
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1  # one frame of a small network: threads cost more than they give
    self.session = ort.InferenceSession(str(self.path), options, providers=["CPUExecutionProvider"])
    self.state: dict = {}

  def start(self, weights_BxM) -> None:
    """The next frame starts over from ``weights`` (a dancer's first frame)."""
    self.weights = np.asarray(weights_BxM, np.float32)
    self.state = {io["name"]: np.zeros(io["shape"], io["dtype"]) for io in self.meta["inputs"][4:]}
    self.starting = np.ones((self.weights.shape[0],), np.float32)

  def step(self, gumbel_BxK, normal_BxD) -> np.ndarray:
    """One frame: normalized features ``[B, D]`` (its joint positions ``[B, J, 3]`` in ``self.joints``)."""
    feed = {"weights": self.weights, "start": self.starting, "gumbel": gumbel_BxK, "normal": normal_BxD, **self.state}
    names = [io["name"] for io in self.meta["outputs"]]
    out = dict(zip(names, self.session.run(names, feed), strict=True))
    self.state = {s["input"]: out[s["output"]] for s in self.meta["state"]}
    self.starting = np.zeros_like(self.starting)
    self.joints = np.asarray(out["positions"])
    return np.asarray(out["frame"])

  def dance(self, weights_BxM, gumbel_TxBxK, normal_TxBxD, joints: bool = False):
    """``[B, T, D]`` normalized frames from a fresh start, one call per frame (``joints``: and the graph's
    joint positions ``[B, T, J, 3]``)."""
    self.start(weights_BxM)
    frames, positions = [], []
    for g, n in zip(gumbel_TxBxK, normal_TxBxD, strict=True):
      frames.append(self.step(g, n))
      positions.append(self.joints)
    return (np.stack(frames, 1), np.stack(positions, 1)) if joints else np.stack(frames, 1)

  def positions(self, z_BxTxD) -> np.ndarray:
    """Joint positions ``[B, T, J, 3]`` in data space: the frames decoded as ``chorjax sample`` decodes."""
    features = Features.from_dict(self.meta["features"])
    return np.asarray(features.decode(np.asarray(z_BxTxD), **self.meta["decoding"]))
