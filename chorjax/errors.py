"""User-facing errors and safe file writing.

A ``UserError`` is bad input from the user (a malformed file, an unknown config key, a missing
checkpoint). The CLI prints its message as one line and exits with code 2, without a traceback.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path


class UserError(Exception):
  """Bad input from the user; its message is one line that names the file/line or key."""


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
  fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix or ".tmp", dir=path.parent)
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


def read_text(path, kind: str, errors: str = "strict") -> str:
  """A text file's contents, or a one-line ``UserError`` naming the file (``kind``: e.g. "BVH")."""
  path = Path(path)
  try:
    return path.read_text(encoding="utf-8", errors=errors)
  except FileNotFoundError:
    raise UserError(f"{path}: no such {kind} file") from None
  except (UnicodeDecodeError, IsADirectoryError, PermissionError) as e:
    raise UserError(f"{path}: cannot read as a {kind} text file ({type(e).__name__})") from None


def first_non_number(cells) -> int:
  """Index of the first cell that does not parse as a float, for line errors (called after one failed)."""
  for i, c in enumerate(cells):
    try:
      float(c)
    except ValueError:
      return i
  raise ValueError("every cell parses as a number")
