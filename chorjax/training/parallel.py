"""Data parallelism with JAX's own runtime: a device mesh with a ``data`` axis, on one host or many.

* The global batch (``train.batch_size``) is sharded over the mesh's ``data`` axis; parameters and
  optimizer state are replicated; the train step is jitted with explicit in/out shardings.
* Multi-host: ``jax.distributed.initialize`` (coordinator, process count and id from the config,
  the CLI, or the cluster environment, e.g. SLURM). Each process builds only its own rows of every
  batch (the row indices of the whole batch are a cheap, deterministic function of seed and step)
  and ``jax.make_array_from_process_local_data`` assembles the global array.
* Only process 0 writes logs, metrics, samples and reports; orbax writes checkpoints collectively.
  Checkpoints hold replicated arrays, so a run can resume on a different number of processes.
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

from chorjax.errors import UserError


@dataclasses.dataclass(frozen=True, eq=False)
class Parallel:
  """The mesh and shardings of a data-parallel run."""

  mesh: Mesh
  batch_size: int

  @property
  def batch_sharding(self) -> NamedSharding:
    return NamedSharding(self.mesh, P("data"))

  @property
  def replicated(self) -> NamedSharding:
    return NamedSharding(self.mesh, P())

  @property
  def process_index(self) -> int:
    return jax.process_index()

  @property
  def process_count(self) -> int:
    return jax.process_count()

  @property
  def is_main(self) -> bool:
    return jax.process_index() == 0

  def local_rows(self) -> slice:
    """The rows of the global batch that this process's devices hold (contiguous, in order)."""
    per = self.batch_size // self.process_count
    return slice(self.process_index * per, (self.process_index + 1) * per)

  def global_batch(self, sampler, step: int) -> dict:
    """Builds this process's share of batch ``step`` and assembles the global arrays."""
    local = sampler.batch(step, self.local_rows())
    return {
      k: jax.make_array_from_process_local_data(self.batch_sharding, v, (self.batch_size,) + v.shape[1:])
      for k, v in local.items()
    }

  def replicate(self, tree):
    """Host values -> arrays replicated on every device of the mesh (works across processes)."""

    def put(x):
      x = np.asarray(x)
      return jax.make_array_from_callback(x.shape, self.replicated, lambda idx: x[idx])

    return jax.tree.map(put, tree)

  def local_copy(self, tree):
    """Replicated global arrays -> this process's copy on its first device (for generation)."""
    return jax.tree.map(lambda x: jax.device_put(np.asarray(x.addressable_data(0)), jax.local_devices()[0]), tree)


def initialize_distributed(pcfg) -> None:
  """``jax.distributed.initialize`` from the config; unset values come from the environment."""
  if jax.distributed.is_initialized():
    return
  kwargs = {}
  if pcfg.coordinator_address:
    kwargs["coordinator_address"] = pcfg.coordinator_address
  if pcfg.num_processes:
    kwargs["num_processes"] = pcfg.num_processes
  if pcfg.process_id >= 0:
    kwargs["process_id"] = pcfg.process_id
  try:
    jax.distributed.initialize(**kwargs)
  except (ValueError, RuntimeError) as e:
    raise UserError(f"parallel.distributed: jax.distributed.initialize failed: {str(e).splitlines()[0]}") from None


def setup_parallel(cfg) -> Parallel | None:
  """The run's ``Parallel`` (None when the config asks for neither data parallelism nor distribution)."""
  pcfg = cfg.parallel
  if pcfg.distributed:
    initialize_distributed(pcfg)
  if not (pcfg.data_parallel or pcfg.distributed):
    return None
  devices = jax.devices()
  if pcfg.num_devices:
    if pcfg.num_devices > len(devices):
      raise UserError(f"parallel.num_devices={pcfg.num_devices}, but only {len(devices)} devices exist")
    if pcfg.num_devices % jax.process_count():
      raise UserError(
        f"parallel.num_devices={pcfg.num_devices} must be a multiple of the {jax.process_count()} processes"
      )
    per = pcfg.num_devices // jax.process_count()
    devices = [d for p in range(jax.process_count()) for d in [x for x in devices if x.process_index == p][:per]]
  if cfg.train.batch_size % len(devices):
    raise UserError(
      f"train.batch_size={cfg.train.batch_size} must be divisible by the {len(devices)} devices "
      "of the data-parallel mesh"
    )
  devices = sorted(devices, key=lambda d: (d.process_index, d.id))
  return Parallel(Mesh(np.array(devices), ("data",)), cfg.train.batch_size)
