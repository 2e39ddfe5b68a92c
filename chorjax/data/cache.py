"""Reading a library once: every take, parsed and encoded, kept on disk and found again by its content.

Two kinds of entries, each one ``.npz`` file under the cache folder (``data.cache``):

- ``takes/``: the motions a file holds, as its reader made them, keyed by the file's path and bytes and the
  reader's settings (a CSV's skeleton, frame rate and up axis). A changed file has another key: it is read
  again, and only it.
- ``features/``: a take's canonical positions and its encoded versions (the augmentations), keyed by the
  take's positions after mapping and resampling and by the settings that encode them. Whatever changes
  upstream (a file, the joint mapping, the frame rate, a ``data.*`` key) changes the key.

A library's files and takes not yet in the cache are parsed and encoded in fresh processes
(``in_processes``, ``data.workers``), which write their entries; the reading process then reads them back.
An entry is written whole (through a temporary file) and checked when read: one that cannot be read or does
not hold what its key says is damaged, said in one line, and made again; it is never trusted. Entries are
never removed by chorjax: delete the folder to reclaim its space.
"""

from __future__ import annotations

import concurrent.futures
import hashlib
import json
import multiprocessing
import os
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from chorjax.data.motion import Motion, Skeleton
from chorjax.errors import atomic_write

FORMAT = 1  # bump when what an entry holds changes meaning: old entries are then never found


def cache_root(setting: str) -> Path | None:
  """The cache folder of ``data.cache``: ``auto`` is ``$CHORJAX_CACHE``, else ``$XDG_CACHE_HOME/chorjax``,
  else ``~/.cache/chorjax``; ``off`` keeps nothing; anything else is the folder."""
  if setting == "off":
    return None
  if setting != "auto":
    return Path(setting).expanduser()
  if os.environ.get("CHORJAX_CACHE"):
    return Path(os.environ["CHORJAX_CACHE"])
  base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
  return Path(base) / "chorjax"


def digest(*parts) -> str:
  """A key from bytes, arrays and JSON-able settings."""
  h = hashlib.blake2b(digest_size=20)
  h.update(str(FORMAT).encode())
  for part in parts:
    if isinstance(part, np.ndarray):
      h.update(str((part.dtype.str, part.shape)).encode())
      h.update(np.ascontiguousarray(part).tobytes())
    elif isinstance(part, bytes):
      h.update(part)
    else:
      h.update(json.dumps(part, sort_keys=True, default=str).encode())
    h.update(b"\0")
  return h.hexdigest()


class Cache:
  """The entries under one folder (``root`` None: nothing is kept, everything is made each time). An entry's
  key is computed once per cache object: asking whether it is kept and then reading it hashes a file once."""

  def __init__(self, root: Path | None):
    self.root, self.keys = root, {}

  def motions(self, path: Path, settings: dict, read: Callable[[], list[Motion]]) -> list[Motion]:
    """The motions of the file ``path`` (``read()`` parses it), from the cache when its bytes were read before
    with these reader ``settings``."""
    if self.root is None:
      return read()
    return self._entry("takes", self._motions_key(path, settings), read, _save_motions, _load_motions, f"{path}")

  def _motions_key(self, path: Path, settings: dict) -> str:
    # the path as given, not resolved: a take's name comes from it, and two links to one file are two takes
    where = str(Path(path).absolute())
    return self._key(("takes", where, digest(settings)), lambda: digest(where, Path(path).read_bytes(), settings))

  def _encoded_key(self, motion: Motion, settings: dict) -> str:
    make = lambda: digest(np.asarray(motion.positions, np.float32), motion.skeleton.to_dict(), motion.fps, settings)
    return self._key(("features", id(motion), digest(settings)), make, motion)

  def _key(self, memo: tuple, make: Callable[[], str], owner=None) -> str:
    """``make()``, once per ``memo`` (for ``owner``: an id is only that object's while it lives)."""
    kept = self.keys.get(memo)
    if kept is None or kept[0] is not owner:
      kept = self.keys[memo] = (owner, make())
    return kept[1]

  def _path(self, kind: str, key: str) -> Path:
    assert self.root is not None
    return self.root / kind / key[:2] / f"{key}.npz"

  def has_motions(self, path: Path, settings: dict) -> bool:
    """Whether the file's motions are kept (an entry that turns out damaged is made again when read)."""
    return self.root is not None and self._path("takes", self._motions_key(path, settings)).exists()

  def has_encoded(self, motion: Motion, settings: dict) -> bool:
    return self.root is not None and self._path("features", self._encoded_key(motion, settings)).exists()

  def encoded(self, motion: Motion, settings: dict, make: Callable[[], dict], check=None) -> dict:
    """``make()``'s arrays for ``motion`` (``{name: array}``), from the cache when the same positions were
    encoded with these ``settings`` before; ``check(arrays)`` raises ValueError for an entry that cannot be
    this motion's (made again, as a damaged one is)."""
    if self.root is None:
      return make()
    key = self._encoded_key(motion, settings)
    load = _load_arrays if check is None else lambda path, k: check(_load_arrays(path, k))
    return self._entry("features", key, make, _save_arrays, load, motion.source or motion.name)

  def _entry(self, kind: str, key: str, make, save, load, what: str):
    path = self._path(kind, key)
    if path.exists() and not path.is_file():  # a FIFO or a device would block the read forever: never opened
      print(f"cache: {path} is not a file; {what} is read again", file=sys.stderr, flush=True)
    elif path.exists():
      try:
        return load(path, key)
      except Exception as e:  # anything that cannot be read back is damage: made again, never trusted
        why = f"{type(e).__name__}: {str(e)[:80]}" if str(e) else type(e).__name__
        print(f"cache: {path} was damaged ({why}); {what} is read again", file=sys.stderr, flush=True)
    value = make()
    try:
      atomic_write(path, lambda tmp: save(tmp, key, value))
    except OSError as e:  # a full or read-only disk costs the cache, not the run
      print(f"cache: {path} not written ({e}); reading goes on without it", file=sys.stderr, flush=True)
    return value


def _save_arrays(tmp: Path, key: str, arrays: dict) -> None:
  with open(tmp, "wb") as f:
    np.savez(f, __key__=np.array(key), **arrays)


def _load_arrays(path: Path, key: str) -> dict:
  with np.load(path, allow_pickle=False) as data:
    if str(data["__key__"]) != key:
      raise ValueError("holds another entry")
    return {k: np.asarray(data[k]) for k in data.files if k != "__key__"}


def _save_motions(tmp: Path, key: str, motions: list[Motion]) -> None:
  meta = [
    {"fps": m.fps, "skeleton": m.skeleton.to_dict(), "up_axis": m.up_axis, "units": m.units, "name": m.name}
    | {"source": m.source}
    for m in motions
  ]
  arrays = {f"positions_{k}": np.asarray(m.positions, np.float32) for k, m in enumerate(motions)}
  _save_arrays(tmp, key, {"meta": np.array(json.dumps(meta)), **arrays})


def _load_motions(path: Path, key: str) -> list[Motion]:
  arrays = _load_arrays(path, key)
  meta = json.loads(str(arrays["meta"]))
  return [
    Motion(
      arrays[f"positions_{k}"],
      float(m["fps"]),
      Skeleton.from_dict(m["skeleton"]),
      m["up_axis"],
      m["units"],
      m["name"],
      m["source"],
    )
    for k, m in enumerate(meta)
  ]


PARALLEL_MIN = 64  # entries to make before ``workers = 0`` (auto) starts processes: each costs seconds to start


def workers_for(setting: int, missing: int) -> int:
  """How many processes make ``missing`` entries: ``data.workers`` when set, else (0) every core once there are
  at least ``PARALLEL_MIN`` to make, else 1 (this process)."""
  if setting > 0:
    return setting
  return max(1, min(os.cpu_count() or 1, missing // (PARALLEL_MIN // 2))) if missing >= PARALLEL_MIN else 1


def in_processes(fn: Callable, items: list, workers: int) -> None:
  """``fn(item)`` for every item, in ``workers`` fresh processes (each writes its entries into the cache; the
  caller then reads them). A worker's UserError (a bad file) reaches the caller as it is."""
  context = multiprocessing.get_context("spawn")  # jax is threaded: a forked copy of it can deadlock
  with concurrent.futures.ProcessPoolExecutor(workers, mp_context=context) as pool:
    for _ in pool.map(fn, items, chunksize=max(1, len(items) // (8 * workers))):
      pass
