"""Test set-up: 4 host devices for the data-parallel tests, quick compiles, and one XLA compilation cache for the
whole run (all must precede the first jax import)."""

import atexit
import os
import shutil
import tempfile
from pathlib import Path

import pytest

# Quick compiles: most of a tiny test is XLA compiling programs that then run for milliseconds. LLVM's
# optimizations off and XLA's older (quicker to compile) fusion emitters take a third off the suite. They change
# no program's meaning, only last bits, so tests/test_draws.py, which holds the draws to recorded digests,
# makes them in a process of its own with these flags taken out: as a user's programs compile.
QUICK_COMPILE = "--xla_backend_optimization_level=0 --xla_cpu_use_fusion_emitters=false"
os.environ.setdefault("XLA_FLAGS", f"--xla_force_host_platform_device_count=4 {QUICK_COMPILE}")
os.environ.setdefault("JAX_PLATFORMS", "cpu")
os.environ.setdefault("CHORJAX_DEBUG", "1")  # a bug raises in tests (the CLI's last-resort line would hide it)

# Most of the suite's time is XLA compiling tiny programs, and the same ones compile again in each xdist
# worker and CLI subprocess: pytest's first process makes one persistent cache (a fresh temporary folder,
# removed at exit) that the workers and every subprocess inherit. Every program is cached, however quick.
if "JAX_COMPILATION_CACHE_DIR" not in os.environ and "PYTEST_XDIST_WORKER" not in os.environ:
  _xla_cache = tempfile.mkdtemp(prefix="chorjax-tests-xla-")
  os.environ["JAX_COMPILATION_CACHE_DIR"] = _xla_cache
  atexit.register(shutil.rmtree, _xla_cache, ignore_errors=True)
# The same for the takes read and encoded (data.cache = "auto" finds $CHORJAX_CACHE): one fresh folder per run,
# so no test reads what an earlier run left, and nothing is written under the user's ~/.cache.
if "CHORJAX_CACHE" not in os.environ and "PYTEST_XDIST_WORKER" not in os.environ:
  _takes_cache = tempfile.mkdtemp(prefix="chorjax-tests-takes-")
  os.environ["CHORJAX_CACHE"] = _takes_cache
  atexit.register(shutil.rmtree, _takes_cache, ignore_errors=True)
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES", "-1")
# jax writes an entry in place, so a process reading it while another writes it finds it cut short, says
# so and compiles again: harmless, and not what a test of a command's output is about.
_race = "ignore:Error reading persistent compilation cache entry"
os.environ["PYTHONWARNINGS"] = ",".join(w for w in (os.environ.get("PYTHONWARNINGS"), _race) if w)

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
  """The real recordings in ../shared/data (CI has them beside the clone)."""
  assert SHARED.is_dir(), f"{SHARED} is missing: tests read the real recordings from ../shared/data"
  return SHARED


# The test files by how long they take (seconds of one worker on 2 cores, `--durations 0`), longest first.
# xdist hands whole files to its two workers in collection order, each taking the next when it runs dry: the
# long files go first and the short ones fill in the end (a 45 s file collected last leaves one worker idle
# for most of that). A file not listed goes after these; the order is a schedule, not a dependency.
LONGEST_FIRST = (
  "test_draws.py",  # 85
  "test_live.py",  # 71
  "test_train.py",  # 69
  "test_parallel.py",  # 57
  "test_models.py",  # 49
  "test_sample_render.py",  # 45
  "test_metrics.py",  # 45
  "test_guides.py",  # 40
  "test_labels.py",  # 36
  "test_gan.py",  # 35
  "test_calibrate.py",  # 34
  "test_vectorized.py",  # 32
  "test_formats.py",  # 28
  "test_export.py",  # 27
  "test_notebook.py",  # 27
  "test_inbetween.py",  # 25
  "test_transforms.py",  # 24
  "test_bad_inputs.py",  # 20
  "test_one_skeleton.py",  # 18
  "test_dataset.py",  # 17
  "test_own_data.py",  # 11
)


def pytest_collection_modifyitems(config, items):
  rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
  items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: a file's own order is kept
