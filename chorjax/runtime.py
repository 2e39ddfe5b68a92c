"""Process-level settings that make training on CPU faster.

XLA:CPU allocates each executable's scratch memory (hundreds of MB for a training step) per call and
frees it afterwards. With glibc's default settings, a block that large comes from ``mmap`` and goes
back with ``munmap``, so every training step page-faults its whole scratch buffer again (about 76,000
faults, ~0.19 s of kernel time per step of the reference model; see BENCHMARKS.md).
:func:`keep_freed_memory` tells glibc to serve large blocks from one heap and not to give freed memory
back, so the next step reuses the same pages.

It must run before the first JAX computation (XLA's worker threads pick their malloc arena when they
start); the ``chorjax`` command calls it first thing. Set ``CHORJAX_MALLOC=system`` to keep glibc's
defaults. It does nothing where the C library is not glibc.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import platform

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
