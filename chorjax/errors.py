"""User-facing errors and safe file writing.

A ``UserError`` is bad input from the user (a malformed file, an unknown config key, a missing
checkpoint). The CLI prints its message as one line and exits with code 2, without a traceback.
"""

from __future__ import annotations

import glob
import json
import math
import os
import re
import tempfile
import tomllib
from collections.abc import Callable
from pathlib import Path

import numpy as np


class UserError(Exception):
  """Bad input from the user; its message is one line that names the file/line or key (a line break or other
  control character in what it quotes, such as a file name holding a newline, is written as an escape)."""

  def __init__(self, message: str = "", *args):
    super().__init__(_one_line(str(message)), *args)


def _one_line(text: str) -> str:
  """``text`` with control characters (newlines, carriage returns, escapes) as ``\\n``-style escapes."""
  return "".join(c if c.isprintable() or c == " " else repr(c)[1:-1] for c in text)


class Interrupted(Exception):
  """Work stopped by a signal after saving what it had; ``code`` is the exit status (128 + signal)."""

  def __init__(self, message: str, code: int):
    super().__init__(message)
    self.code = code


def atomic_write(path: str | os.PathLike, write: Callable[[Path], object], *, overwrite: bool = True) -> Path:
  """Writes a file through a temporary sibling and renames it into place.

  Nothing is half written: if ``write`` fails, the target is untouched and the temporary is removed.

  Args:
    path: the final file path.
    write: called with the temporary path; must create the file there.
    overwrite: if False and ``path`` exists, raise ``UserError`` instead of replacing it.

  Returns:
    The final path.
  """
  path = Path(path)
  if not overwrite and path.exists():
    raise UserError(f"{path}: already exists (refusing to overwrite; remove it or choose another name)")
  path.parent.mkdir(parents=True, exist_ok=True)
  _clean_stale(path)
  fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.tmp{os.getpid()}.", suffix=path.suffix or ".tmp", dir=path.parent)
  os.close(fd)
  tmp_path = Path(tmp)
  try:
    write(tmp_path)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp_path, 0o666 & ~umask)  # mkstemp creates 0600; give the file ordinary permissions
    os.replace(tmp_path, path)
  finally:
    if tmp_path.exists():
      tmp_path.unlink()
  return path


def _clean_stale(path: Path) -> None:
  """Removes temporaries of ``path`` left by a killed write (their process is gone)."""
  for tmp in path.parent.glob(f".{glob.escape(path.stem)}.tmp*"):
    pid = tmp.name[len(path.stem) + 5 :].split(".")[0]
    if pid.isdigit() and not _alive(int(pid)):
      tmp.unlink(missing_ok=True)


def _alive(pid: int) -> bool:
  try:
    os.kill(pid, 0)
  except ProcessLookupError:
    return False
  except (PermissionError, OverflowError):
    return pid < 2**22  # someone else's process (or an impossible number: not a process)
  return True


def read_text(path, kind: str, errors: str = "strict") -> str:
  """A text file's contents (a UTF-8 byte-order mark dropped), or a one-line ``UserError`` naming the file
  (``kind``: e.g. "BVH"); anything but a regular file (a named pipe would block forever) is refused."""
  path = Path(path)
  if path.exists() and not path.is_file() and not path.is_dir():
    raise UserError(f"{path}: not a regular file (a pipe or a device); chorjax reads files whole")
  if path.is_file():  # text, its lines and the numbers parsed from them: about 16 bytes a byte of file, at most
    size = path.stat().st_size
    check_memory(size * 16, f"{path}: a {size:,}-byte {kind} file, read whole")
  try:
    return path.read_text(encoding="utf-8-sig", errors=errors)
  except FileNotFoundError:
    raise UserError(f"{path}: no such {kind} file") from None
  except (UnicodeDecodeError, IsADirectoryError, PermissionError) as e:
    raise UserError(f"{path}: cannot read as a {kind} text file ({type(e).__name__})") from None


def load_json(text: str):
  """``json.loads``, with nesting too deep for the parser (a RecursionError) raised as a ``JSONDecodeError``
  like any other malformed JSON, so every reader's one-line error covers it."""
  try:
    return json.loads(text)
  except RecursionError:
    raise json.JSONDecodeError("nested too deeply", text[:100], 0) from None


def load_toml(text: str) -> dict:
  """``tomllib.loads``, with nesting too deep for the parser raised as a ``TOMLDecodeError``."""
  try:
    return tomllib.loads(text)
  except RecursionError:
    raise tomllib.TOMLDecodeError("nested too deeply") from None


def read_toml(path, kind: str) -> dict:
  """A TOML file's tables (``kind``: e.g. "sweep"), or a one-line ``UserError`` naming the file: missing,
  unreadable (:func:`read_text`) or not valid TOML."""
  try:
    return load_toml(read_text(path, kind))
  except tomllib.TOMLDecodeError as e:
    raise UserError(f"{path}: invalid TOML: {e}") from None


RATES = (1.0, 1000.0)  # frames per second that motion capture uses (30-120 fps; high-speed 240-960)
UP_AXES = ("y", "-y", "z", "-z", "x", "-x")


def check_rate(fps, where: str) -> float:
  """``fps`` as a float, or a one-line UserError (``where`` names the file or flag) when it is not a
  finite rate within ``RATES``: a header's ``Frame Time: 999`` or a rate of 0 is refused when read, not
  divided by later."""
  try:
    rate = float(fps)
  except (TypeError, ValueError):
    raise UserError(f"{where}: frame rate {fps!r} is not a number") from None
  if not (RATES[0] <= rate <= RATES[1]):  # also false for nan
    raise UserError(f"{where}: frame rate {rate:g} fps is outside {RATES[0]:g}-{RATES[1]:g} fps")
  return rate


def check_up_axis(axis, where: str) -> str:
  """``axis`` if it is one of ``UP_AXES``, else a one-line UserError."""
  if axis not in UP_AXES:
    raise UserError(f"{where}: up axis {axis!r} is not one of {', '.join(UP_AXES)}")
  return axis


# no motion capture value (a coordinate in any unit, an angle in degrees) comes near this: larger is garbage
LARGEST_VALUE = 1e7


# Numbers as motion capture tools write them: ASCII digits, an optional sign, point and exponent. Python's
# float() and int() also take underscores (1_000) and other scripts' digits, which no such tool writes.
_DECIMAL = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?", re.ASCII)
# the same for a line's cells, each followed by NUL (one way to match each: no backtracking blow-up on a long line)
_CELLS = re.compile(r"(?:\s*[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?\s*\0)*", re.ASCII)
_WHOLE = re.compile(r"[+-]?\d+", re.ASCII)


def whole_number(text: str) -> int:
  """``int(text)`` for ASCII decimal digits only; ``ValueError`` otherwise."""
  if not _WHOLE.fullmatch(text.strip()):
    raise ValueError(f"not a whole number: {text!r}")
  return int(text)


def parse_numbers(cells, where: str, columns: bool = False) -> list[float]:
  """The floats in ``cells`` (one line of a text file), or a one-line ``UserError`` starting with
  ``where`` (``path:line``; with ``columns``, the 1-based column too) for the first cell that is not a
  plain decimal number, not finite (nan, inf) or beyond +-``LARGEST_VALUE``."""
  cells = list(cells)
  if _CELLS.fullmatch("\0".join(cells) + "\0"):  # every cell plain (the common case): one check for the line
    try:
      values = list(map(float, cells))
    except ValueError:  # a cell holding the separator; the loop below names it
      values = None
    if values is not None and (not values or max(map(abs, values)) <= LARGEST_VALUE):
      return values
  values = []
  for i, c in enumerate(cells):
    at = f"{where}: column {i + 1}" if columns else where
    try:
      v = float(c)
    except ValueError:
      raise UserError(f"{at}: not a number: {c.strip()[:40]!r}") from None
    if not math.isfinite(v):
      raise UserError(f"{at}: non-finite value {c.strip()!r}")
    if not _DECIMAL.fullmatch(c.strip()):
      raise UserError(f"{at}: not a plain decimal number: {c.strip()[:40]!r} (ASCII digits, no underscores)")
    if abs(v) > LARGEST_VALUE:
      raise UserError(f"{at}: value {c.strip()[:40]} is out of range (beyond +-{LARGEST_VALUE:g})")
    values.append(v)
  return values


def memory_bytes() -> int:
  """This machine's physical memory in bytes (what any one allocation must stay under)."""
  try:
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
  except (ValueError, OSError, AttributeError):
    return 16 << 30


def check_memory(nbytes: float, what: str) -> None:
  """One-line ``UserError`` naming ``what`` (the flags or keys that set the size) when ``nbytes``, estimated
  before allocating, is more than half this machine's memory (the other half is the program and its data)."""
  limit = memory_bytes() / 2
  if nbytes > limit:
    raise UserError(
      f"{what}: needs about {nbytes / 2**30:,.3g} GiB, more than half this machine's memory "
      f"({limit / 2**30:.3g} GiB is the limit); ask for less"
    )


def check_draw(frames: int, values_per_frame: int, what: str) -> None:
  """Refuses a draw of ``frames`` frames (frames x dancers) of ``values_per_frame`` values each (features and
  positions) that this machine cannot hold: float64, a few copies on the way out (``check_memory``)."""
  check_memory(frames * values_per_frame * 8 * 6, what)


def check_array(values, where: str) -> None:
  """One-line ``UserError`` naming ``where`` if ``values`` hold a non-finite entry or one beyond
  +-``LARGEST_VALUE`` (binary formats: the text readers check each line with :func:`parse_numbers`)."""
  a = np.asarray(values)
  bad = ~np.isfinite(a) | (np.abs(np.nan_to_num(a)) > LARGEST_VALUE)
  if bad.any():
    idx = tuple(int(k) for k in np.argwhere(bad)[0])
    kind = "non-finite" if not np.isfinite(a[idx]) else "out-of-range"
    raise UserError(f"{where}: {kind} value {a[idx]!r} at index {list(idx)} ({int(bad.sum())} such values)")


def as_path(value, what: str = "path") -> Path:
  """``value`` as a ``Path``, or a one-line ``UserError`` when it is no path (None, a number, text holding a
  NUL byte, which no file system takes)."""
  if not isinstance(value, str | os.PathLike):
    raise UserError(f"{what} {value!r}: expected a file path")
  text = os.fspath(value)
  if not isinstance(text, str) or "\x00" in text or not text:
    raise UserError(f"{what} {str(text)[:60]!r}: not a usable file path")
  return Path(text)


def either(words) -> str:
  """``a, b or c`` (one word alone as itself, none as ``none``): the choices an error line names."""
  words = list(words) or ["none"]
  return words[0] if len(words) == 1 else f"{', '.join(words[:-1])} or {words[-1]}"


def check_output(path, allowed: tuple[str, ...]) -> tuple[Path, str]:
  """The output path and its suffix, checked to be one of the ``allowed`` suffixes."""
  out = as_path(path, "output")
  suffix = out.suffix.lower()
  if suffix not in allowed:
    raise UserError(f"{out}: output must end in {either(allowed)}")
  return out, suffix


def is_run_folder(path) -> bool:
  """Whether the folder ``path`` holds a chorjax run (its config or its checkpoints: a run that has started)."""
  return Path(path).is_dir() and bool({p.name for p in Path(path).iterdir()} & {"config.json", "checkpoints"})


def refuse_existing(paths, force: bool, how: str = "--force") -> None:
  """A UserError for the first of ``paths`` that exists, unless ``force`` (``how`` says how to allow it)."""
  for p in paths:
    if Path(p).exists() and not force:
      raise UserError(f"{p}: already exists (use {how} to overwrite)")
