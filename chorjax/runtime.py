"""Process-level settings that make a command faster: freed memory kept for reuse, compiled programs kept on
disk, independent draws side by side.

XLA:CPU allocates each executable's scratch memory (hundreds of MB for a training step) per call and
frees it afterwards. With glibc's default settings, a block that large comes from ``mmap`` and goes
back with ``munmap``, so every training step page-faults its whole scratch buffer again
(``docs/perf-notes.md`` has the figures).
:func:`keep_freed_memory` tells glibc to serve large blocks from one heap and not to give freed memory
back, so the next step reuses the same pages.

It must run before the first JAX computation (XLA's worker threads pick their malloc arena when they
start); the ``chorjax`` command calls it first thing. Set ``CHORJAX_MALLOC=system`` to keep glibc's
defaults. It does nothing where the C library is not glibc.

:func:`keep_compiled_programs` keeps every program XLA compiles (JAX's persistent compilation cache), so that a
command compiles a program once per machine and every later command loads it (what that saves:
``docs/perf-notes.md``). The ``chorjax`` command calls it too.

:func:`side_by_side` runs independent draws (calibration's settings, evaluation's seeds) ``DRAWS_AT_ONCE`` at a
time in threads: a draw's frame loop runs small kernels one after another on one core.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import ctypes
import ctypes.util
import hashlib
import os
import platform
import tempfile
import warnings
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

import jax

from chorjax.data.cache import cache_root

# mallopt parameters (malloc.h)
_M_TRIM_THRESHOLD, _M_MMAP_MAX, _M_ARENA_MAX = -1, -4, -8
_KEEP_BYTES = 2**31 - 1  # (the largest value mallopt takes) keep freed heap memory
_applied: bool | None = None


def keep_freed_memory() -> bool:
  """Configures glibc malloc once per process; returns whether the settings are in effect."""
  global _applied
  if _applied is not None:
    return _applied
  _applied = False
  if os.environ.get("CHORJAX_MALLOC", "").lower() == "system" or platform.libc_ver()[0] != "glibc":
    return False
  try:
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
  except OSError:
    return False
  # One arena (XLA's threads share the main heap), no mmap for large blocks, no trimming.
  _applied = all(
    libc.mallopt(p, v) == 1 for p, v in ((_M_ARENA_MAX, 1), (_M_MMAP_MAX, 0), (_M_TRIM_THRESHOLD, _KEEP_BYTES))
  )
  return _applied


# Draws run this many at a time (threads): calibrating the quick start's run on 2 cores took 34.5 s one at a time,
# 28.0 s two at a time, 28.2 s three, 29.6 s four, every row of its table the same.
DRAWS_AT_ONCE = 2
# The compiled programs kept (bytes): the least recently used go first beyond it. README command 1 (the quick start:
# training, calibration, its sample) keeps 2.1 MB.
COMPILED_BYTES = 2**30


def cpu_info() -> dict[str, str]:
  """The first processor's fields in /proc/cpuinfo (``model name``, ``cpu family``, ``flags``, ...); empty where
  there is no such file."""
  info = {}
  with contextlib.suppress(OSError):
    for line in Path("/proc/cpuinfo").read_text().splitlines():
      if not line.strip():
        break  # the first processor is enough
      key, _, value = line.partition(":")
      info[key.strip()] = value.strip()
  return info


def keep_compiled_programs() -> Path | None:
  """Turns on JAX's persistent compilation cache in ``xla/CPU`` of chorjax's cache folder (``$CHORJAX_CACHE``,
  else ``$XDG_CACHE_HOME/chorjax`` or ``~/.cache/chorjax``), ``CPU`` naming this processor's model and instruction
  sets (a program compiled for one CPU is not loaded on another); returns the folder, or None where it stays off:
  ``CHORJAX_COMPILE_CACHE=off``, a cache folder JAX already has (``JAX_COMPILATION_CACHE_DIR``), or a folder that
  cannot be written. Every program is kept, however quick to compile (``COMPILED_BYTES`` in all, least recently
  used dropped first). A loaded program is the compiled one: the same frames to the bit. An entry that cannot be
  read or written is compiled again without a word."""
  root = cache_root("auto")  # a folder ("off" is the setting that gives none)
  off = os.environ.get("CHORJAX_COMPILE_CACHE", "").lower() == "off"
  if root is None or off or jax.config.values["jax_compilation_cache_dir"]:
    return None
  info = cpu_info()
  cpu = "\n".join([platform.machine(), *(info.get(k, "") for k in ("model name", "cpu family", "model", "flags"))])
  folder = root / "xla" / hashlib.blake2b(cpu.encode(), digest_size=6).hexdigest()
  try:
    folder.mkdir(parents=True, exist_ok=True)
    tempfile.TemporaryFile(dir=folder).close()
  except OSError:
    return None
  jax.config.update("jax_compilation_cache_dir", str(folder))
  jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
  jax.config.update("jax_compilation_cache_max_size", COMPILED_BYTES)
  warnings.filterwarnings("ignore", message="Error (reading|writing) persistent compilation cache entry")
  return folder


def side_by_side(fn: Callable[[Any], Any], items: Iterable, at_once: int | None = None) -> Iterator:
  """``fn(item)`` for each item, in order, ``at_once`` (default ``DRAWS_AT_ONCE``) of them running at a time in
  threads (a draw: each is what it is alone; ``fn`` must allow being called from several threads at once).
  Lazy: a result is yielded as soon as it and those before it are done."""
  with concurrent.futures.ThreadPoolExecutor(at_once or DRAWS_AT_ONCE) as pool:
    yield from pool.map(fn, items)
