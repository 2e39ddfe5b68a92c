"""``chorjax export --web``: a static folder in which a run's dancer dances live in a browser page, offline: the
page (``web_dancer.html`` beside this module), the ONNX dancer and its sidecar (:mod:`chorjax.export.dancer`) and
onnxruntime-web's files, with its licence."""

from __future__ import annotations

import json
import shutil
import tempfile
from importlib.resources import files
from pathlib import Path

import numpy as np

from chorjax.errors import UserError, as_path
from chorjax.export.dancer import export_onnx, needs_onnx, sidecar_path
from chorjax.run import load_run

# onnxruntime-web's files the page loads (its wasm build, single-threaded), from the npm package's dist/
ORT_WEB_FILES = ("ort.wasm.min.js", "ort-wasm-simd-threaded.wasm", "ort-wasm-simd-threaded.mjs")
ORT_WEB_PLACES = ("node_modules/onnxruntime-web/dist", ".venv/node/node_modules/onnxruntime-web/dist")


def find_ort_web(given=None) -> Path:
  """The folder of onnxruntime-web's files: ``given``, else ``node_modules/onnxruntime-web/dist`` here (``npm
  install onnxruntime-web``), else the same under ``.venv/node``."""
  places = [Path(given)] if given else [Path(p) for p in ORT_WEB_PLACES]
  for place in places:
    if all((place / f).is_file() for f in ORT_WEB_FILES):
      return place
  where = f"{given} does not hold {', '.join(ORT_WEB_FILES)}" if given else "npm install onnxruntime-web here"
  raise UserError(f"--web needs onnxruntime-web's files ({where}; or --ort-web PATH/onnxruntime-web/dist)")


WEB_DANCER = "dancer.onnx"  # what write_web puts in its folder: this, its sidecar, the page and ort/
WEB_FILES = ("index.html", WEB_DANCER, sidecar_path(WEB_DANCER).name, "ort")


def write_web(workdir, folder, *, ort_web=None, controls=None, checkpoint="kept", force: bool = False) -> Path:
  """``chorjax export --web``: a static folder in which the run's dancer dances live in the page, offline:
  ``index.html``, the dancer (``dancer.onnx`` and its sidecar) and onnxruntime-web's files (``ort/``, with its
  licence). Any static file server serves it. The page draws the joints the graph decodes (rigid bones; the
  feet neither grounded nor locked). Returns the folder."""
  needs_onnx()
  out = as_path(folder, "--web")
  if out.exists() and (not out.is_dir() or any(out.iterdir())):
    if not force:
      raise UserError(f"{out}: already exists and is not an empty folder (use --force to replace it)")
    _check_web_folder(out)
  ort = find_ort_web(ort_web)
  run = load_run(workdir, checkpoint)
  out.parent.mkdir(parents=True, exist_ok=True)
  staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
  try:
    export_onnx(run, staging / WEB_DANCER, controls=controls)
    (staging / "ort").mkdir()
    for name in ORT_WEB_FILES:
      shutil.copyfile(ort / name, staging / "ort" / name)
    page = files("chorjax.export")
    version = _package_version(ort.parent / "package.json")
    licence = page.joinpath("onnxruntime_web_license.txt").read_text(encoding="utf-8")
    (staging / "ort" / "LICENSE").write_text(licence.replace("{version}", version), encoding="utf-8")
    (staging / "index.html").write_text(page.joinpath("web_dancer.html").read_text(encoding="utf-8"), encoding="utf-8")
    staging.chmod(0o755)  # a folder to serve (mkdtemp makes it private)
    if out.exists():
      shutil.rmtree(out)
    staging.rename(out)
  finally:
    shutil.rmtree(staging, ignore_errors=True)
  return out


def _check_web_folder(out: Path) -> None:
  """A UserError unless ``out`` is a folder that ``--force`` may replace: one that holds only what ``--web``
  writes (a page written before), and neither the working directory nor a folder above it."""
  here = Path.cwd().resolve()
  where = out.resolve()
  if where == here or where in here.parents:
    raise UserError(f"{out}: is the working directory or holds it; --web --force replaces only a page it wrote")
  if not out.is_dir():
    raise UserError(f"{out}: is a file, not a page --web wrote; --force replaces only such a folder")
  ort_files = {*ORT_WEB_FILES, "LICENSE"}
  foreign = sorted(p.name for p in out.iterdir() if p.name not in WEB_FILES)
  if (out / "ort").is_dir():
    foreign += sorted(f"ort/{p.name}" for p in (out / "ort").iterdir() if p.name not in ort_files)
  elif (out / "ort").exists():
    foreign.append("ort")
  if foreign:
    listed = ", ".join(foreign[:3]) + (", ..." if len(foreign) > 3 else "")
    raise UserError(f"{out}: holds files --web did not write ({listed}); --force replaces only a page it wrote")


def _package_version(package_json: Path) -> str:
  try:
    return str(json.loads(package_json.read_text())["version"])
  except (OSError, ValueError, KeyError, TypeError):
    return "(version not recorded)"


def page_numbers(seed: int, frames: int, batch: int, num_gumbel: int, num_normal: int):
  """``(gumbel [T, B, K], normal [T, B, N])``: the random numbers the exported web page draws with ``seed``
  (its mulberry32 stream; Gumbel as ``-log(-log(u))``, normal by Box-Muller's cosine, one pair of uniforms
  each), so that onnxruntime in Python can draw what the page draws."""
  state = seed & 0xFFFFFFFF
  mask = 0xFFFFFFFF

  def imul(a: int, b: int) -> int:
    return (a * b) & mask

  def uniform() -> float:
    nonlocal state
    state = (state + 0x6D2B79F5) & mask
    t = state
    t = imul(t ^ (t >> 15), t | 1)
    t ^= (t + imul(t ^ (t >> 7), t | 61)) & mask
    return (((t ^ (t >> 14)) & mask) + 0.5) / 4294967296

  gumbel = np.zeros((frames, batch, num_gumbel), np.float32)
  normal = np.zeros((frames, batch, num_normal), np.float32)
  for f in range(frames):
    gumbel[f] = np.array([-np.log(-np.log(uniform())) for _ in range(batch * num_gumbel)]).reshape(batch, -1)
    pairs = [(uniform(), uniform()) for _ in range(batch * num_normal)]
    normal[f] = np.array([np.sqrt(-2 * np.log(u1)) * np.cos(2 * np.pi * u2) for u1, u2 in pairs]).reshape(batch, -1)
  return gumbel, normal
