"""Test set-up: 4 host devices for the data-parallel tests (must precede the first jax import)."""

import os
from pathlib import Path

os.environ.setdefault("XLA_FLAGS", "--xla_force_host_platform_device_count=4")
os.environ.setdefault("JAX_PLATFORMS", "cpu")
os.environ.setdefault("CHORJAX_DEBUG", "1")  # a bug raises in tests (the CLI's last-resort line would hide it)

import pytest

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
  """The real recordings in ../shared/data (CI has them beside the clone)."""
  assert SHARED.is_dir(), f"{SHARED} is missing: tests read the real recordings from ../shared/data"
  return SHARED
