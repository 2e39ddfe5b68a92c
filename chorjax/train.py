"""Training: a pure jitted ``train_step``, ``eval_step``, and the driver ``train_and_evaluate``.

The state is a plain pytree ``{params, opt_state, step}``. Randomness comes from
``fold_in(key(seed), step)`` and batches from ``WindowSampler.batch(step)``, so a run resumed from a
checkpoint at step s repeats exactly what the uninterrupted run did after s.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import math
import os
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import nnx

from chorjax import checkpoint as ckpt
from chorjax.config import Config, config_diff, config_from_dict
from chorjax.data.dataset import Dataset, WindowSampler, eval_windows, load_dataset
from chorjax.errors import UserError, atomic_write
from chorjax.models import create_model, motion_weights

# Keys that may change when a run is continued without --force (e.g. to train longer).
RESUMABLE_CHANGES = ("train.num_steps", "train.eval_every", "train.log_every", "train.figure_every",
                     "log.progress", "log.tensorboard", "sample.frames", "sample.num", "sample.seed",
                     # a run may resume on another number of devices or processes
                     "parallel.data_parallel", "parallel.num_devices", "parallel.distributed",
                     "parallel.coordinator_address", "parallel.num_processes", "parallel.process_id")


class TrainingDiverged(UserError):
  """A non-finite loss; the message names the step and the last good checkpoint."""


def create_optimizer(cfg) -> tuple[optax.GradientTransformation, optax.Schedule]:
  """The optax chain of ``cfg.optim``: optional global-norm clipping, then the optimizer."""
  o = cfg.optim
  if o.schedule == "warmup_cosine":
    schedule = optax.warmup_cosine_decay_schedule(0.0, o.lr, o.warmup_steps, max(cfg.train.num_steps, o.warmup_steps + 1),
                                                  end_value=o.lr * o.final_lr_ratio)
  else:
    schedule = optax.constant_schedule(o.lr)
  if o.name == "adam":
    opt = optax.adam(schedule, b1=o.b1, b2=o.b2)
  elif o.name == "adamw":
    opt = optax.adamw(schedule, b1=o.b1, b2=o.b2, weight_decay=o.weight_decay)
  else:
    opt = optax.amsgrad(schedule, b1=o.b1, b2=o.b2)
  chain = [optax.clip_by_global_norm(o.clip_norm)] if o.clip_norm > 0 else []
  return optax.chain(*chain, opt), schedule


def init_state(cfg: Config, dim: int, num_motions: int):
  """``(graphdef, state, tx, schedule)`` for a fresh run."""
  model = create_model(cfg.model, dim, num_motions, cfg.train.seed)
  graphdef, params = nnx.split(model, nnx.Param)
  params = nnx.to_pure_dict(params)
  tx, schedule = create_optimizer(cfg)
  state = {"params": params, "opt_state": tx.init(params), "step": jnp.zeros((), jnp.int32)}
  return graphdef, state, tx, schedule


def _loss_fn(graphdef, params, batch, num_motions, key, input_noise, dropout):
  model = nnx.merge(graphdef, params)
  x = batch["inputs"]
  noise_key, dropout_key = jax.random.split(key)
  if input_noise > 0:
    x = x + input_noise * jax.random.normal(noise_key, x.shape, x.dtype)
  raw = model(x, motion_weights(batch["motion_ids"], num_motions), dropout_key if dropout > 0 else None)
  return model.loss(raw, batch["targets"])


def make_train_step(graphdef, tx, schedule, cfg: Config, num_motions: int, wrap=lambda f: f, parallel=None):
  """The jitted ``train_step(state, batch, key) -> (state, metrics)``; ``state`` is donated.

  ``wrap`` decorates the Python function before jit (tests pass ``chex.assert_max_traces(n=1)``).
  With ``parallel`` the batch is sharded over the mesh's data axis and everything else replicated.
  """
  noise, dropout = cfg.train.input_noise, cfg.model.dropout

  def train_step(state, batch, key):
    if not jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key):
      key = jax.random.wrap_key_data(key)  # raw uint32 key data (replicated across processes)
    key = jax.random.fold_in(key, state["step"])
    grad_fn = jax.value_and_grad(_loss_fn, argnums=1, has_aux=True)
    (loss, aux), grads = grad_fn(graphdef, state["params"], batch, num_motions, key, noise, dropout)
    updates, opt_state = tx.update(grads, state["opt_state"], state["params"])
    params = optax.apply_updates(state["params"], updates)
    metrics = {"loss": loss, **aux, "grad_norm": optax.tree.norm(grads), "param_norm": optax.tree.norm(params),
               "update_norm": optax.tree.norm(updates), "lr": schedule(state["step"])}
    return {"params": params, "opt_state": opt_state, "step": state["step"] + 1}, metrics

  if parallel is None:
    return jax.jit(wrap(train_step), donate_argnums=0)
  repl, data = parallel.replicated, parallel.batch_sharding
  return jax.jit(wrap(train_step), donate_argnums=0, in_shardings=(repl, data, repl), out_shardings=(repl, repl))


def make_eval_step(graphdef, num_motions: int):
  """The jitted ``eval_step(params, batch) -> loss`` (no noise, no dropout)."""

  def eval_step(params, batch):
    model = nnx.merge(graphdef, params)
    raw = model(batch["inputs"], motion_weights(batch["motion_ids"], num_motions))
    return model.loss(raw, batch["targets"])[0]

  return jax.jit(eval_step)


# ---------------------------------------------------------------- run directory


def default_workdir(cfg: Config) -> Path:
  return Path("runs") / cfg.name


@contextlib.contextmanager
def workdir_lock(workdir: Path):
  """An exclusive lock on the workdir; the OS releases it even if the process is killed."""
  workdir.mkdir(parents=True, exist_ok=True)
  f = open(workdir / ".lock", "a+")
  try:
    fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
  except BlockingIOError:
    f.close()
    raise UserError(f"{workdir}: in use by another `chorjax train` (lock {workdir / '.lock'})") from None
  try:
    yield
  finally:
    fcntl.flock(f, fcntl.LOCK_UN)
    f.close()


def _check_saved_config(workdir: Path, cfg: Config, force: bool, may_write: bool = True) -> None:
  """Refuses a workdir whose saved config differs (unless ``force``; then process 0 keeps the old one)."""
  path = workdir / "config.json"
  if not path.exists():
    return
  try:
    saved = config_from_dict(json.loads(path.read_text()))
  except (json.JSONDecodeError, UserError) as e:
    if not force:
      raise UserError(f"{path}: unreadable saved config ({e}); use --force to replace it") from None
    return
  diff = config_diff(saved, cfg, ignore=RESUMABLE_CHANGES)
  if diff and not force:
    raise UserError(f"{workdir}: holds a run with a different config ({'; '.join(diff[:3])}"
                    f"{' ...' if len(diff) > 3 else ''}); use another --workdir, or --force to continue it")
  if diff and may_write:  # keep the old config beside the new one: nothing is overwritten silently
    os.replace(path, workdir / f"config.{int(time.time())}.json")


def _write_config(workdir: Path, cfg: Config) -> None:
  atomic_write(workdir / "config.json", lambda p: p.write_text(json.dumps(cfg.to_dict(), indent=2)))


def _truncate_metrics(path: Path, upto_step: int) -> None:
  """Drops rows logged after the checkpoint we resume from (a killed run may have written them)."""
  if not path.exists():
    return
  rows = [l for l in path.read_text().splitlines() if l.strip()]
  kept = [l for l in rows if json.loads(l).get("step", 0) <= upto_step]
  if len(kept) != len(rows):
    atomic_write(path, lambda p: p.write_text("".join(l + "\n" for l in kept)))


def make_meta(cfg: Config, ds: Dataset, step: int) -> dict:
  return {"config": cfg.to_dict(), "features": ds.features.to_dict(), "id_map": ds.id_map,
          "train_takes": list(ds.train_names), "val_takes": list(ds.val_names),
          "rng": {"seed": cfg.train.seed, "fold_in": "step"},
          "sampler": {"seed": cfg.train.seed, "position": step}, "step": step}


class _Progress:
  """A rich progress bar on a terminal; plain periodic lines otherwise (CI, cluster logs)."""

  def __init__(self, mode: str, total: int, start: int):
    if mode == "auto":
      mode = "bar" if sys.stdout.isatty() else "lines"
    self.mode = mode
    self.total, self.bar = total, None
    if self.mode == "bar":
      from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
      self.bar = Progress(TextColumn("train"), BarColumn(), MofNCompleteColumn(), TextColumn("{task.fields[info]}"),
                          TimeRemainingColumn())
      self.task = self.bar.add_task("train", total=total, completed=start, info="")
      self.bar.start()

  def update(self, step: int, row: dict, eta_s: float):
    info = f"loss {row['train_loss']:.4g}" + (f" val {row['val_loss']:.4g}" if "val_loss" in row else "")
    if self.mode == "bar":
      self.bar.update(self.task, completed=step, info=info)
    elif self.mode == "lines":
      print(f"step {step}/{self.total} {info} {row.get('steps_per_s', 0):.1f} steps/s ETA {eta_s:.0f}s", flush=True)

  def close(self):
    if self.bar is not None:
      self.bar.stop()


def _finite_or_raise(metrics: dict, step: int, last_good: int | None):
  loss = float(metrics["loss"])
  if not math.isfinite(loss):
    where = f"step {last_good}" if last_good is not None else "none (no checkpoint was written yet)"
    raise TrainingDiverged(f"non-finite loss ({loss}) at step {step}; training stopped; last good checkpoint: {where}")
  return loss


def train_and_evaluate(cfg: Config, workdir, *, force: bool = False, parallel=None) -> dict:
  """Trains ``cfg`` in ``workdir``, resuming from its latest checkpoint; returns a summary.

  Writes ``config.json``, ``metrics.jsonl``, TensorBoard events, ``checkpoints/`` and, at the end,
  ``samples/`` (a short sample and its HTML player). With ``parallel`` (see ``chorjax.parallel``)
  every process trains its share and only process 0 writes anything but checkpoints.
  """
  workdir = Path(workdir).absolute()
  is_main = parallel is None or parallel.is_main
  with workdir_lock(workdir) if is_main else contextlib.nullcontext():
    _check_saved_config(workdir, cfg, force, may_write=is_main)
    return _train_locked(cfg, workdir, parallel)


def _train_locked(cfg: Config, workdir: Path, parallel) -> dict:
  t_start = time.time()
  ds = load_dataset(cfg.data)
  if cfg.sample.frames > 0:  # fail now, not after hours of training, if the end sample cannot be drawn
    from chorjax.sample import motion_weight_vector
    motion_weight_vector(ds.num_motions, cfg.sample.motion, source="sample.motion =")
  graphdef, state, tx, schedule = init_state(cfg, ds.features.dim, ds.num_motions)
  is_main = parallel is None or parallel.is_main
  manager = ckpt.create_manager(workdir, keep=cfg.train.keep_checkpoints)
  writer = None
  progress = None
  try:
    start = 0
    if manager.latest_step() is not None:
      start = manager.latest_step()
      meta = ckpt.step_meta(manager, start)
      if meta["id_map"] != ds.id_map:
        raise UserError(f"{workdir}: its checkpoints were trained on other takes ({list(meta['id_map'])[:3]}...)")
      state = ckpt.restore(manager, start, state, None if parallel is None else parallel.replicated)
    if is_main:
      _write_config(workdir, cfg)
      _truncate_metrics(workdir / "metrics.jsonl", start)
    if cfg.log.tensorboard and is_main:
      from tensorboardX import SummaryWriter
      writer = SummaryWriter(str(workdir), flush_secs=10)

    sampler = WindowSampler(ds.train, cfg.data.seq_length, cfg.train.batch_size, cfg.train.seed)
    val = eval_windows(ds.val, cfg.data.seq_length, cfg.train.val_windows)
    train_step = make_train_step(graphdef, tx, schedule, cfg, ds.num_motions, parallel=parallel)
    eval_step = make_eval_step(graphdef, ds.num_motions)
    base_key = jax.random.key(cfg.train.seed)
    get_batch = sampler.batch
    host_params = lambda params: params
    if parallel is not None:
      state = parallel.replicate(state)
      val = parallel.replicate(val)
      base_key = parallel.replicate(jax.random.key_data(base_key))
      get_batch = lambda s: parallel.global_batch(sampler, s)
      host_params = parallel.local_copy

    total = cfg.train.num_steps
    progress = _Progress(cfg.log.progress if is_main else "none", total, start)
    last_good = start if start > 0 else None
    pending = None  # (step, metrics) pulled to the host one step late
    t_last, steps_since = time.time(), 0
    summary = {"start_step": start, "final_step": start, "train_losses": {}}
    compile_s = None

    def log(step, metrics, val_loss=None):
      nonlocal t_last, steps_since
      loss = _finite_or_raise(metrics, step, last_good)
      summary["train_losses"][step] = loss
      summary["final_train_loss"] = loss
      if not is_main or (step % cfg.train.log_every and val_loss is None and step != total):
        return
      now = time.time()
      sps = steps_since / max(now - t_last, 1e-9)
      t_last, steps_since = now, 0
      row = {"step": step, "train_loss": loss, **{k: float(v) for k, v in metrics.items() if k != "loss"},
             "steps_per_s": sps}
      if val_loss is not None:
        row["val_loss"] = val_loss
      with open(workdir / "metrics.jsonl", "a") as f:  # process 0 only
        f.write(json.dumps(row) + "\n")
      if writer is not None:
        for k, v in row.items():
          if k != "step":
            writer.add_scalar(("val/" if k == "val_loss" else "train/") + k.removeprefix("train_"), v, step)
      progress.update(step, row, (total - step) / max(sps, 1e-9))
      if val_loss is not None:
        summary["final_val_loss"] = val_loss

    for step in range(start, total):
      t0 = time.time()
      state, metrics = train_step(state, get_batch(step), base_key)
      if compile_s is None:
        jax.block_until_ready(metrics["loss"])
        compile_s = time.time() - t0
      steps_since += 1
      if pending is not None:
        log(*pending)
      pending = (step + 1, metrics)
      done = step + 1
      eval_due = cfg.train.eval_every and done % cfg.train.eval_every == 0
      ckpt_due = done % cfg.train.checkpoint_every == 0 or done == total
      if eval_due or ckpt_due:
        val_loss = float(eval_step(state["params"], val)) if val and (eval_due or done == total) else None
        log(*pending, val_loss=val_loss)  # checks the loss is finite before anything is saved
        pending = None
        if ckpt_due:
          ckpt.save(manager, done, state, make_meta(cfg, ds, done), val_loss)
          last_good = done
        if writer is not None and cfg.train.figure_every and done % cfg.train.figure_every == 0:
          _figure(writer, graphdef, host_params(state["params"]), ds, cfg, done)
      summary["final_step"] = done
    if pending is not None:
      log(*pending)
    manager.wait_until_finished()
    summary.update(seconds=time.time() - t_start, compile_s=compile_s)
    if is_main and cfg.sample.frames > 0 and total > 0:
      summary["samples"] = _write_end_sample(workdir, graphdef, host_params(state["params"]), ds, cfg)
    return summary
  finally:
    if progress is not None:
      progress.close()
    manager.wait_until_finished()
    manager.close()
    if writer is not None:
      writer.close()


def _figure(writer, graphdef, params, ds, cfg, step):
  """A short generated sample beside a real one, as a TensorBoard figure."""
  try:
    from chorjax.render.plot import require_matplotlib
    plt = require_matplotlib()
  except UserError:
    return
  from chorjax.sample import generate
  n = 120
  w = motion_weights(jnp.array([ds.val[0][0] if ds.val else ds.train[0][0]]), ds.num_motions)
  s = cfg.sample  # drawn as the run's own samples are
  z = generate(graphdef, params, w, jax.random.key(step), num_frames=n, pi_temperature=s.pi_temperature,
               sigma_temperature=s.sigma_temperature, greedy=s.greedy)
  gen = np.asarray(ds.features.decode(z[0]))
  real_z = (ds.val or ds.train)[0][1][:n]
  real = np.asarray(ds.features.decode(real_z))
  sk = ds.features.skeleton
  fig, axes = plt.subplots(1, 2, figsize=(10, 3), sharey=True)
  for ax, pos, title in ((axes[0], real, "real"), (axes[1], gen, "generated")):
    for j in sk.end_joints:
      ax.plot(pos[:, j, 1], lw=1, label=sk.joint_names[j])
    ax.set_title(f"{title}: end joints, vertical axis")
  axes[0].legend(fontsize=6)
  writer.add_figure("sample/end_joints", fig, step)
  plt.close(fig)


def _write_end_sample(workdir: Path, graphdef, params, ds: Dataset, cfg: Config) -> dict:
  """``samples/sample.csv`` and ``samples/player.html``: the dance the run ends with."""
  from chorjax.sample import generate
  from chorjax.render.html import write_player
  from chorjax.data.csv import write_csv
  from chorjax.data.motion import Motion

  s = cfg.sample
  w = jnp.tile(motion_weights(jnp.array([s.motion]), ds.num_motions), (s.num, 1))
  z = generate(graphdef, params, w, jax.random.key(s.seed), num_frames=s.frames,
               pi_temperature=s.pi_temperature, sigma_temperature=s.sigma_temperature, greedy=s.greedy)
  pos = np.asarray(ds.features.decode(z))
  out = workdir / "samples"
  csv = write_csv(pos[0], out / "sample.csv")
  name = {v: k for k, v in ds.id_map.items()}[s.motion]
  sk = ds.features.skeleton
  real = ds.motions[s.motion]
  motions = [real.replace(positions=real.positions[: s.frames], name=f"original: {name}")]
  motions += [Motion(p, real.fps, sk, real.up_axis, real.units, name=f"generated #{i} (motion {s.motion})")
              for i, p in enumerate(pos)]
  # originals above, generated below (the reference notebook's catalog page)
  html = write_player(motions, out / "player.html", title=f"chorjax: {cfg.name}", columns=max(s.num, 1),
                      rows=[0] + [1] * s.num)
  return {"csv": str(csv), "html": str(html)}
