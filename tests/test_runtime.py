"""The process-level settings: a jitted step must not page-fault its scratch memory anew, and a program compiled
once is loaded by every later command."""

import os
import platform
import subprocess
import sys
from pathlib import Path

import pytest

# A jitted function whose scratch memory (~100 MB) is far above glibc's largest mmap threshold.
_CODE = """
import resource, sys
from chorjax.runtime import keep_freed_memory
applied = keep_freed_memory()
import jax, jax.numpy as jnp
f = jax.jit(lambda x: jnp.sum(jnp.tanh(x @ x.T) @ x) + jnp.sum(jnp.exp(x @ x.T)))
x = jnp.ones((5000, 256)) * 0.01
for _ in range(3):  # the heap settles over the first calls
  f(x).block_until_ready()
faults = []
for _ in range(5):
  r0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
  f(x).block_until_ready()
  faults.append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - r0)
print(applied, min(faults))  # the fewest: a call now and then may still grow the heap
"""


def _faults_per_call(env_value):
  env = {**os.environ, "CHORJAX_MALLOC": env_value, "JAX_PLATFORMS": "cpu"}
  env.pop("XLA_FLAGS", None)
  out = subprocess.run([sys.executable, "-c", _CODE], capture_output=True, text=True, env=env, check=True)
  applied, faults = out.stdout.split()
  return applied == "True", float(faults)


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="the setting is for glibc malloc")
def test_keeping_freed_memory_removes_the_per_call_page_faults():
  default_applied, default_faults = _faults_per_call("system")
  assert not default_applied
  assert default_faults > 10_000  # ~100 MB of scratch, faulted in again on every call
  # With the setting, a call reuses the pages the last one had. The kernel may still reclaim idle pages of a
  # process while another one (a second test worker) presses on memory: then every call of that run faults,
  # so the run is measured again, up to three times (seen once in CI: 24,414 faults against 24,415).
  for _ in range(3):
    applied, faults = _faults_per_call("")
    assert applied
    if faults < default_faults / 20:
      break
  assert faults < default_faults / 20


LEGACY_RUN = Path(__file__).resolve().parent / "fixtures" / "legacy_run"


def _sample(out: Path, cache: Path, **env):
  """``chorjax sample`` of the checked-in run in a process of its own (JAX's cache is set once per process),
  with chorjax's cache folder ``cache`` and none of the suite's compilation cache settings (tests/conftest.py)."""
  ours = {k: v for k, v in os.environ.items() if not k.startswith(("JAX_COMPILATION_CACHE", "JAX_PERSISTENT_CACHE"))}
  env = ours | {"CHORJAX_CACHE": str(cache)} | env
  argv = [sys.executable, "-m", "chorjax.cli", "sample", str(LEGACY_RUN), "-o", str(out), "--frames", "24"]
  return subprocess.run(argv, capture_output=True, text=True, env=env)


def test_a_second_command_loads_every_program_the_first_compiled(tmp_path):
  first = _sample(tmp_path / "first.csv", tmp_path / "cache")
  assert first.returncode == 0 and first.stderr == "", first.stderr
  (folder,) = (tmp_path / "cache" / "xla").iterdir()  # one folder for this CPU
  kept = sorted(folder.glob("*-cache"))
  assert len(kept) >= 3
  second = _sample(tmp_path / "second.csv", tmp_path / "cache", JAX_LOG_COMPILES="1")
  assert second.returncode == 0, second.stderr
  compiled = second.stderr.count("Finished XLA compilation of")
  assert compiled >= len(kept) and second.stderr.count("Persistent compilation cache hit") == compiled, second.stderr
  assert (tmp_path / "second.csv").read_bytes() == (tmp_path / "first.csv").read_bytes()
  assert sorted(folder.glob("*-cache")) == kept
  off = _sample(tmp_path / "off.csv", tmp_path / "cache_off", CHORJAX_COMPILE_CACHE="off")
  assert off.returncode == 0 and not (tmp_path / "cache_off" / "xla").exists(), off.stderr


def test_no_compilation_cache_where_it_cannot_be_written_or_one_is_set(tmp_path, monkeypatch):
  import jax

  from chorjax.runtime import keep_compiled_programs

  configured = jax.config.jax_compilation_cache_dir  # the suite's own (tests/conftest.py): kept
  assert configured and keep_compiled_programs() is None and jax.config.jax_compilation_cache_dir == configured
  (tmp_path / "a_file").write_text("")
  monkeypatch.setenv("CHORJAX_CACHE", str(tmp_path / "a_file"))  # a cache folder that cannot be made
  jax.config.update("jax_compilation_cache_dir", None)
  try:
    assert keep_compiled_programs() is None and jax.config.jax_compilation_cache_dir is None
  finally:
    jax.config.update("jax_compilation_cache_dir", configured)
