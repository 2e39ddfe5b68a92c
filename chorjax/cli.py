"""The ``chorjax`` command line: one small function per subcommand.

User errors print one line (``chorjax: error: ...``) and exit with code 2, without a traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import math
import os
import sys
from pathlib import Path

from rich.console import Console

from chorjax import api
from chorjax.api import Interrupted, UserError


def _data_info(args) -> int:
  Console(width=200).print(api.takes_table(args.inputs))
  return 0


def _data_plot(args) -> int:
  print(f"wrote {api.plot_file(args.input, args.output, split=args.split)}")
  return 0


def _data_check(args) -> int:
  table, lines, fatal = api.check_report(args.inputs, joint_map=args.joint_map, fps=args.fps)
  Console(width=200).print(table)
  print("\n".join(lines))
  for line in fatal:
    print(f"chorjax: error: {line}", file=sys.stderr)
  return 2 if fatal else 0


def _data_convert(args) -> int:
  options = {k: getattr(args, k) for k in CONVERT_OPTIONS}
  for path, m in api.convert(args.inputs, args.output, **options):
    print(f"wrote {path} ({m.num_frames} frames, {m.skeleton.num_joints} joints, {m.fps:g} fps, up {m.up_axis})")
  return 0


CONVERT_OPTIONS = (
  "joints",
  "joint_map",
  "like",
  "up_axis",
  "scale",
  "asf",
  "amc_fps",
  "fps",
  "drop_first_frame",
  "keep_rest_frames",
  "rigid",
  "skeleton",
  "force",
)


def _config_show(args) -> int:
  config, overrides = args.config, list(args.overrides)
  if config and "=" in config and not Path(config).exists():  # only overrides of the defaults
    config, overrides = None, [config, *overrides]
  print(api.to_toml(api.load_config(config, overrides)), end="")
  return 0


def _config_keys(args) -> int:
  if args.markdown:
    print(api.reference_markdown(), end="")
    return 0
  for row in api.key_docs(args.prefix):
    print(f"{row['key']} = {api.toml_value(row['default'])}\n    {api.key_help(row['key'])}")
    if args.more and row["more"]:
      print(f"    {row['more']}")
  return 0


PARALLEL_FLAGS = (
  ("coordinator", "coordinator_address"),
  ("num_processes", "num_processes"),
  ("process_id", "process_id"),
)


def _train(args) -> int:
  overrides = [*args.overrides, *(["parallel.distributed=true"] if args.distributed else [])]
  for flag, key in PARALLEL_FLAGS:
    value = getattr(args, flag)
    if value is not None:
      overrides.append(f"parallel.{key}={value!r}" if isinstance(value, str) else f"parallel.{key}={value}")
  api.train_command(args.config, overrides, workdir=args.workdir, force=args.force, log=print)
  return 0


def _sample(args) -> int:
  _counts(args, frames=1, num=1)
  draw = {k: getattr(args, k) for k in ("frames", "num", "seed", "prime", "motion", "mix", "checkpoint", "skeleton")}
  written = api.write_sample(args.workdir, args.output, **draw, controls=_controls(args), force=args.force)
  print("wrote " + ", ".join(map(str, written)))
  return 0


def _serve(site, port: int | None) -> int:
  """Serves the folder ``site`` on this machine only (127.0.0.1) until interrupted; ``port`` None: says how."""
  if port is None:
    print(
      f"wrote {site}: a browser loads its dancer only from a server, not from disk: serve it with "
      f"--serve, or python3 -m http.server --directory {site}"
    )
    return 0
  import functools
  from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer

  quiet = type("Quiet", (SimpleHTTPRequestHandler,), {"log_message": lambda *a: None})
  try:
    server = ThreadingHTTPServer(("127.0.0.1", port), functools.partial(quiet, directory=str(site)))
  except OSError as e:
    raise api.UserError(f"--serve {port}: cannot listen on 127.0.0.1:{port} ({e.strerror or e})") from None
  print(f"wrote {site}; serving it at http://127.0.0.1:{server.server_address[1]}/ (Ctrl-C stops)", flush=True)
  with server, contextlib.suppress(KeyboardInterrupt):
    server.serve_forever()
  return 0


def _export(args) -> int:
  common = {"controls": _controls(args), "checkpoint": args.checkpoint, "force": args.force}
  if args.web is not None:
    if args.output is not None or args.batch != 1:
      raise api.UserError("--web writes a folder with one dancer: no -o or --batch with it")
    return _serve(api.write_web(args.workdir, args.web, ort_web=args.ort_web, **common), args.serve)
  if args.serve is not None:
    raise api.UserError("--serve serves the page --web DIR writes: give --web DIR")
  if args.output is None:
    raise api.UserError("export: give -o DANCER.onnx or --web DIR")
  print("wrote " + ", ".join(map(str, api.write_onnx(args.workdir, args.output, batch=args.batch, **common))))
  return 0


def _blender_addon(args) -> int:
  print(f"wrote {api.write_blender_addon(args.output, force=args.force)} (Blender: Preferences > Add-ons > Install)")
  return 0


def _inbetween(args) -> int:
  _counts(args, num=1)
  kw = {"start": args.from_, "to": args.to, "frames": args.frames, "seed": args.seed, "num": args.num}
  written = api.write_inbetween(args.workdir, args.output, **kw, checkpoint=args.checkpoint, force=args.force)
  print("wrote " + ", ".join(map(str, written)))
  return 0


def _live(args) -> int:
  served = {k: getattr(args, k) for k in ("host", "port", "fps", "seed", "motion", "mix", "osc", "osc_in", "alternate")}
  served |= {"input_spec": args.input, "record": args.record, "checkpoint": args.checkpoint, "force": args.force}
  ready = lambda line: print(line, flush=True)
  return api.run_live(args.workdir, **served, controls=_controls(args), allow_origins=args.allow_origin, on_ready=ready)


def _render(args) -> int:
  _counts(args, frames=1, every=1, poses=1, columns=1)
  options = {k: getattr(args, k) for k in ("frames", "fps", "size", "columns", "title", "strip", "every", "poses")}
  warn = lambda line: print(line, file=sys.stderr)
  print(f"wrote {api.render(args.inputs, args.output, **options, force=args.force, warn=warn)}")
  return 0


def _eval(args) -> int:
  _counts(args, frames=2, num=1)
  kw = {k: getattr(args, k) for k in ("frames", "num", "checkpoint", "seed", "seeds")}
  result, out = api.evaluate_to(args.workdir, args.data, args.output, force=args.force, **kw, **_controls(args))
  print("\n".join(api.metric_lines(result, ("heldout_loss", *api.METRIC_KEYS))))
  print(f"wrote {out}")
  return 0


def _calibrate(args) -> int:
  _counts(args, frames=60, num=1)
  kw = {k: getattr(args, k) for k in ("frames", "num", "seed", "noise_order", "pace", "force")}
  api.calibrate_run(args.workdir, args.data, **kw)
  return 0


def _metrics(args) -> int:
  _counts(args, window=4, splits=1)
  kw = {"window": args.window, "splits": args.splits, "seed": args.seed}
  result, out = api.score_to(args.motions, args.data, args.output, force=args.force, **kw)
  print("\n".join(api.metric_lines(result, api.METRIC_KEYS)))
  if out is not None:
    print(f"wrote {out}")
  return 0


def _sweep(args) -> int:
  workdirs = api.run_sweep(args.sweep, shard=args.shard)
  print("points: " + " ".join(map(str, workdirs)))
  return 0


def _compare(args) -> int:
  print(f"wrote {api.compare_to(args.workdirs, args.output, force=args.force)}")
  return 0


def _counts(args, **minimum) -> None:
  """Refuses count flags below their minimum (``--frames 0``, ``--num -2``) with one line."""
  for name, low in minimum.items():
    v = getattr(args, name)
    if v is not None and v < low:
      raise UserError(f"--{name} {v}: must be at least {low}")


def _controls(args) -> dict:
  """The sampling flags given on the command line, checked as the same keys are in a config file
  (unset ones are None: the run's calibration, then its config)."""
  numbers = [k for k in api.Controls.names() if k not in api.CONTROL_SWITCHES]
  given = {k: getattr(args, k) for k in numbers}
  for name, value in given.items():
    if value is not None:
      api.check_sample_control(name, value, f"--{name.replace('_', '-')}")
  switches = {k: getattr(args, k) for k in api.CONTROL_SWITCHES}
  chosen = {**given, **switches}
  if getattr(args, "plain", False):
    both = [k for k in api.PLAIN if chosen[k] is not None]
    if both:
      raise UserError(f"--plain is the model's own draw: not with --{both[0].replace('_', '-')}")
    chosen.update(api.PLAIN)
  return chosen


def _add_motion_args(p) -> None:
  """``--motion`` or ``--mix``: what conditions the dance (sample, live)."""
  ids = p.add_mutually_exclusive_group()
  ids.add_argument(
    "--motion",
    type=_motion,
    metavar="ID|LABELS",
    help="motion id that conditions the dance (default 0); a labelled run's labels: action=walk,style=elderly",
  )
  ids.add_argument(
    "--mix",
    metavar="ID:W,ID:W",
    help="blend motion ids, e.g. 4:0.5,5:0.5 (weights >= 0, normalized to sum 1); labels:"
    " style=elderly:0.5,style=active:0.5",
  )


def _motion(text: str):
  """``--motion``: a take id (a whole number), else a labelled run's ``FIELD=VALUE,...``."""
  try:
    return int(text)
  except ValueError:
    if "=" not in text:
      raise argparse.ArgumentTypeError(f"{text!r} is neither a motion id nor FIELD=VALUE labels") from None
    return text


def _add_checkpoint_args(p) -> None:
  """``--checkpoint`` and ``--force`` (commands that read a run and write a file)."""
  p.add_argument(
    "--checkpoint",
    default="kept",
    metavar="STEP|best|latest|kept",
    help="which checkpoint: a step, the best validation loss, the latest, or the one the run keeps "
    "(default kept: its train.keep, the latest unless set to best)",
  )
  p.add_argument("--force", action="store_true", help="overwrite the output if it exists")


def _control_help(name: str) -> str:
  """A sampling flag's help: its ``[sample]`` key's, and where an unset flag's value comes from."""
  return _key_flag(f"sample.{name}", "the run's calibration, else the run's" if name in api.CALIBRATED else "the run's")


def _key_flag(key: str, whose: str) -> str:
  """The help of a flag that sets ``key``: the key's help, and that unset it is ``whose`` value of the key."""
  return f"{api.key_help(key)} (default: {whose} {key})"


def _add_sampling_args(p, seed: bool = True) -> None:
  """Sampling controls shared by `sample`, `eval` and `export`; unset ones come from the run's calibration.json
  (`chorjax calibrate`), else its [sample] config."""
  for name, record in api.RECORDS.items():
    if record.metavar:  # a number: its type is its default's
      kind = type(getattr(api.Controls(), name))
      p.add_argument(f"--{name.replace('_', '-')}", type=kind, metavar=record.metavar, help=_control_help(name))
  p.add_argument(
    "--plain",
    action="store_true",
    help="the model's own draw: temperatures 1 and every other draw control off; decoding (rigid bones, feet) "
    "as the run's",
  )
  for name in api.CONTROL_SWITCHES:
    p.add_argument(f"--{name.replace('_', '-')}", action=argparse.BooleanOptionalAction, help=_control_help(name))
  if seed:
    p.add_argument(
      "--seed", type=_seed, default=0, help="sampling seed: the same seed draws the same dance (default 0)"
    )
  _add_checkpoint_args(p)


def _add_convert_command(dsub) -> None:
  conv = dsub.add_parser("convert", help="convert BVH, ASF/AMC, C3D or CSV takes to the training CSV layout or to BVH")
  conv.add_argument("inputs", nargs="+", metavar="IN", help="motion files or folders")
  conv.add_argument(
    "-o",
    "--output",
    required=True,
    metavar="DIR|OUT.bvh",
    help="a folder (one CSV per take: 3*J columns, no header) or one .bvh file",
  )
  conv.add_argument(
    "--joints",
    choices=("mpii16", "native"),
    default="native",
    help="map onto the 16-joint training layout (automatic for common rigs: by family, joint names or "
    "topology; else --joint-map), or keep all joints (default native)",
  )
  conv.add_argument(
    "--joint-map",
    metavar="MAP.toml",
    help='with --joints mpii16: the source joint of each training joint, one `target = "joint"` line each '
    "(default: automatic)",
  )
  conv.add_argument(
    "--like",
    metavar="DATASET",
    help="match DATASET's body size, up axis, frame rate and average root position (e.g. cmu94), "
    "so the takes can join it",
  )
  conv.add_argument("--up-axis", choices=("y", "-y", "z", "-z", "x", "-x"), help="rotate to this up axis")
  conv.add_argument("--scale", type=_scale, default=1.0, help="multiply lengths (after --like; default 1)")
  conv.add_argument("--asf", metavar="PATH", help="the skeleton of AMC inputs (default: found in the AMC's folder)")
  conv.add_argument("--amc-fps", type=_rate, default=120.0, help="frame rate of AMC inputs (default 120)")
  conv.add_argument("--fps", type=_rate, default=30.0, help="frame rate of CSV inputs (default 30)")
  conv.add_argument(
    "--drop-first-frame", action="store_true", help="drop frame 0 whatever it holds (instead of the rest-pose check)"
  )
  conv.add_argument(
    "--keep-rest-frames",
    action="store_true",
    help="keep a leading rest pose (by default a converter's arms-out frame 0 and the blend out of it are "
    "found by the jump they make and dropped, with a note)",
  )
  conv.add_argument(
    "--rigid",
    action="store_true",
    help="BVH: rigid bones of mean length (rotations only) instead of exact per-frame offsets",
  )
  conv.add_argument(
    "--skeleton",
    metavar="CHARACTER.bvh",
    help="with -o OUT.bvh: write the motion on this character's hierarchy, names, offsets and rest pose by "
    "inverse kinematics (default: the motion's own skeleton)",
  )
  conv.add_argument("--force", action="store_true", help="overwrite outputs that exist")
  conv.set_defaults(func=_data_convert)


def _add_data_commands(sub) -> None:
  """`chorjax data info|plot|convert` and `chorjax config show`."""
  data = sub.add_parser("data", help="inspect and plot motion data")
  dsub = data.add_subparsers(dest="data_command", required=True, metavar="DATA_COMMAND")
  info = dsub.add_parser("info", help="per take: frames, joints, fps, value ranges, bone lengths and CV")
  info.add_argument(
    "inputs", nargs="+", metavar="PATH_OR_NAME", help="a bundled dataset (cmu94), a folder of takes, or a file"
  )
  info.set_defaults(func=_data_info)
  plot = dsub.add_parser("plot", help="pelvis and end joints over time (first 200 frames, the rest) as PNG")
  plot.add_argument("input", metavar="PATH", help="one motion file")
  plot.add_argument("-o", "--output", required=True, metavar="FILE.png", help="the PNG to write (required)")
  plot.add_argument("--split", type=_in_range(1, 10**7), default=200, help="frames in the first row (default 200)")
  plot.set_defaults(func=_data_plot)
  check = dsub.add_parser(
    "check",
    help="per take and for the set: frames, rate, units and up axis (with the evidence), skeleton and mapping, "
    "bone stability, gaps, root jumps, the floor; the config keys to use; exit 2 on a fatal problem",
  )
  check.add_argument("inputs", nargs="+", metavar="PATH", help="motion files, folders or a bundled dataset name")
  check.add_argument("--joint-map", metavar="MAP.toml", help="map skeletons by this file (default: automatic)")
  check.add_argument("--fps", type=_rate, default=30.0, help="frame rate of CSV inputs (default 30)")
  check.set_defaults(func=_data_check)
  _add_convert_command(dsub)

  config = sub.add_parser("config", help="inspect run configs")
  csub = config.add_subparsers(dest="config_command", required=True, metavar="CONFIG_COMMAND")
  show = csub.add_parser("show", help="print the resolved config (file + overrides) as TOML")
  show.add_argument("config", nargs="?", metavar="CONFIG", help="a TOML config (default: the built-in defaults)")
  show.add_argument("overrides", nargs="*", metavar="KEY=VALUE", help="dotted overrides, e.g. model.cell=gru")
  show.set_defaults(func=_config_show)
  keys = csub.add_parser("keys", help="every config key with its default and help (PREFIX: a section or key)")
  keys.add_argument("prefix", nargs="?", default="", metavar="PREFIX", help="e.g. sample or model.cell (default: all)")
  keys.add_argument("--more", action="store_true", help="also the longer notes some keys carry")
  keys.add_argument("--markdown", action="store_true", help="every key as the docs' reference page (docs/config.md)")
  keys.set_defaults(func=_config_keys)


def _add_run_commands(sub) -> None:
  """`chorjax train`, `sample` and `render`."""
  train = sub.add_parser("train", help="train a model from a config; resumes from the workdir's latest checkpoint")
  train.add_argument("config", metavar="CONFIG", help="a TOML config, e.g. configs/quickstart.toml")
  train.add_argument("overrides", nargs="*", metavar="KEY=VALUE", help="dotted overrides, e.g. optim.lr=3e-4")
  train.add_argument("--workdir", help="run directory (default: runs/<config name>)")
  train.add_argument(
    "--force",
    action="store_true",
    help="continue a workdir whose saved config differs (the old config is kept beside it)",
  )
  train.add_argument("--distributed", action="store_true", help=_key_flag("parallel.distributed", "its config's"))
  train.add_argument(
    "--coordinator", metavar="HOST:PORT", help=_key_flag("parallel.coordinator_address", "its config's")
  )
  train.add_argument("--num-processes", type=int, help=_key_flag("parallel.num_processes", "its config's"))
  train.add_argument("--process-id", type=int, help=_key_flag("parallel.process_id", "its config's"))
  train.set_defaults(func=_train)

  sample = sub.add_parser(
    "sample",
    help="generate new dance from a trained run",
    description="Generates new dance from a trained run; unset sampling controls take the run's calibration, then its"
    " [sample] keys. A GAN run draws from noise: no --prime, --motion or --mix.",
  )
  sample.add_argument("workdir", metavar="WORKDIR", help="a run directory with checkpoints")
  sample.add_argument(
    "-o",
    "--output",
    required=True,
    metavar="OUT",
    help="OUT.csv (data layout; K>1 writes OUT_k.csv), OUT.bvh (for Blender; K>1: OUT_k.bvh), OUT.glb "
    "(glTF), OUT.npz (all dancers + settings) or OUT.html",
  )
  sample.add_argument("--frames", type=int, default=1000, help="frames to generate (default 1000)")
  sample.add_argument("--num", type=int, default=1, help="dancers generated in parallel (default 1)")
  _add_motion_args(sample)
  sample.add_argument(
    "--prime", metavar="FILE[:START:LEN]", help="continue a real phrase (chor-rnn's collaboration mode)"
  )
  sample.add_argument(
    "--skeleton",
    metavar="CHARACTER.bvh",
    help="with -o OUT.bvh: the dance on this character's hierarchy, joint names, offsets and rest pose "
    "(inverse kinematics; mapped joints driven, the rest at rest; default: the 16-joint skeleton)",
  )
  _add_sampling_args(sample)
  sample.set_defaults(func=_sample)

  _add_inbetween_command(sub)
  _add_render_command(sub)
  _add_live_command(sub)
  _add_export_command(sub)
  _add_blender_addon_command(sub)


def _add_export_command(sub) -> None:
  """`chorjax export`."""
  p = sub.add_parser(
    "export",
    help="a trained dancer as an ONNX model (one frame a call) with a JSON sidecar",
    description="Writes the run's one-frame draw as an ONNX graph (onnxruntime, Unity, the browser) and DANCER.json"
    " beside it: skeleton, fps, features, controls, the graph's inputs and outputs (docs/guides/export.md).",
  )
  p.add_argument("workdir", metavar="WORKDIR", help="a run directory with checkpoints")
  p.add_argument("-o", "--output", metavar="DANCER.onnx", help="the ONNX file (DANCER.json beside it)")
  p.add_argument(
    "--batch", type=_in_range(1, 4096), default=1, help="dancers the graph draws a call, each its own (default 1)"
  )
  p.add_argument(
    "--web", metavar="DIR", help="instead: a static folder (index.html, the dancer, onnxruntime-web) to serve"
  )
  p.add_argument(
    "--serve",
    type=_in_range(0, 65535),
    nargs="?",
    const=8000,
    metavar="PORT",
    help="--web: then serve the folder at http://127.0.0.1:PORT/ until Ctrl-C (default 8000; 0: any free port)",
  )
  p.add_argument(
    "--ort-web",
    metavar="PATH",
    help="onnxruntime-web's dist folder (default: node_modules/onnxruntime-web/dist here, or under .venv/node)",
  )
  _add_sampling_args(p, seed=False)
  p.set_defaults(func=_export)


def _add_blender_addon_command(sub) -> None:
  """`chorjax blender-addon`."""
  p = sub.add_parser(
    "blender-addon",
    help="the Blender add-on: a dance file or chorjax live onto the selected armature",
    description="Writes the Blender add-on as a zip to install in Blender: it imports a chorjax .npz/.csv onto the"
    " selected armature as an action, and poses it live from chorjax live (docs/guides/export.md).",
  )
  p.add_argument("-o", "--output", metavar="ZIP", default="chorjax_blender.zip", help="default chorjax_blender.zip")
  p.add_argument("--force", action="store_true", help="overwrite an existing zip")
  p.set_defaults(func=_blender_addon)


def _add_inbetween_command(sub) -> None:
  """`chorjax inbetween`."""
  p = sub.add_parser(
    "inbetween",
    help="write the movement between a phrase and key poses (an in-betweening run)",
    description="Writes the frames between a phrase (--from) and key poses (--to) with an in-betweening run: LEN "
    "context frames, N written frames, the target (docs/guides/inbetween.md).",
  )
  p.add_argument("workdir", metavar="WORKDIR", help="an in-betweening run directory with checkpoints")
  p.add_argument(
    "--from",
    dest="from_",
    required=True,
    metavar="FILE[:START:LEN]",
    help="the context phrase (default: the whole take)",
  )
  p.add_argument(
    "--to",
    required=True,
    action="append",
    metavar="FILE[:FRAME]",
    help="a target pose (default frame 0); repeat to chain",
  )
  p.add_argument(
    "--frames", required=True, type=int, action="append", metavar="N", help="frames written before each target"
  )
  p.add_argument("--seed", type=_seed, default=0, help="seed of the transitions' noise (default 0)")
  p.add_argument("--num", type=int, default=1, help="transitions written in parallel, each its own piece (default 1)")
  p.add_argument(
    "-o",
    "--output",
    required=True,
    metavar="OUT",
    help="OUT.csv (K>1 writes OUT_k.csv), OUT.bvh (K>1: OUT_k.bvh), OUT.npz (all pieces + settings) or OUT.html",
  )
  _add_checkpoint_args(p)
  p.set_defaults(func=_inbetween)


def _add_live_command(sub) -> None:
  """`chorjax live`."""
  live = sub.add_parser(
    "live",
    help="dance in real time: a live page and a WebSocket stream (and OSC) that clients steer",
    description="Dances without end: a live player page at GET /, a WebSocket at /ws that clients steer, OSC out and "
    "in. Ctrl-C stops it (docs/guides/live.md).",
  )
  live.add_argument("workdir", metavar="WORKDIR", help="a run directory with checkpoints")
  live.add_argument("--host", default="127.0.0.1", help="address to serve on (default 127.0.0.1)")
  live.add_argument("--port", type=int, default=8765, help="port to serve on, 0 = any free one (default 8765)")
  live.add_argument("--osc", metavar="HOST:PORT", help="also send every frame as OSC /chorjax/frame (default: off)")
  live.add_argument(
    "--osc-in",
    metavar="HOST:PORT",
    help="listen for OSC /chorjax/input, /chorjax/prime, /chorjax/set, /chorjax/pause (default: off)",
  )
  live.add_argument("--fps", type=_rate, help="frames sent per second (default: the run's frame rate)")
  _add_motion_args(live)
  live.add_argument(
    "--alternate",
    type=float,
    default=0.0,
    metavar="SECONDS",
    help="take turns: the input (--input or OSC /chorjax/input) dances SECONDS, then the model continues "
    "from it for SECONDS (default 0: the model alone)",
  )
  live.add_argument(
    "--input", metavar="FILE[:START:LEN]", help="a take played as if live for --alternate (default: none)"
  )
  live.add_argument(
    "--record", metavar="OUT.npz", help="write every frame sent to OUT.npz when stopped (default: not recorded)"
  )
  live.add_argument(
    "--allow-origin",
    action="append",
    default=[],
    metavar="ORIGIN",
    help="also let WebSocket clients from this page origin in (repeatable; `null`: a page opened from a file; "
    "default: only the page this server serves, and programs that send no Origin)",
  )
  _add_sampling_args(live)
  live.set_defaults(func=_live)


SWEEP_DESCRIPTION = (
  "Trains and evaluates every point of a grid over config keys; finished points are skipped,\n"
  "so an interrupted sweep continues where it stopped (docs/guides/sweeps.md)."
)
SWEEP_FORMAT = """The sweep file (TOML):
  name = "lr_sweep"                      # run directories are named NAME-KEY=VALUE-...
  base = "../configs/quickstart.toml"    # the config every point starts from (relative to this file)
  root = "runs/lr_sweep"                 # where the run directories go (relative to the working directory)
  vectorize = ["train.seed"]             # points differing only in these train as one program (optional;
                                         # train.seed, optim.lr, train.input_noise)
  [set]                                  # keys set for every point (optional)
  "train.num_steps" = 1000
  [grid]                                 # every combination of these values is one point
  "optim.lr" = [1e-3, 3e-3]
  "train.seed" = [0, 1, 2]
  [candidates.canonical]                 # named variants, each crossed with the grid (optional)
  "data.representation" = "canonical"
  [eval]                                 # chorjax eval after training (optional): data, frames,
  data = ["cmu94"]                       # num, seed, seeds, splits, window and the sampling
  seeds = [0, 1, 2, 3]                   # controls (pi_temperature, noise_smoothing, ...)

Split over N cluster jobs: chorjax sweep FILE --shard I/N (job I of 0..N-1 runs points I, I+N, ...).
Then: chorjax compare ROOT/* -o report.md"""


def _shard(text: str) -> tuple[int, int]:
  try:
    i, n = (int(x) for x in text.split("/"))
  except ValueError:
    raise argparse.ArgumentTypeError(f"{text!r} is not I/N (e.g. 0/4)") from None
  if not 0 <= i < n:
    raise argparse.ArgumentTypeError(f"{text!r}: needs 0 <= I < N")
  return i, n


def _add_render_command(sub) -> None:
  """`chorjax render`."""
  render = sub.add_parser("render", help="draw motion files or samples as PNG, GIF, MP4 or an HTML player")
  render.add_argument(
    "inputs", nargs="+", metavar="INPUT", help="motion files (.csv, .npz, .bvh, .amc, .c3d), folders or cmu94"
  )
  render.add_argument(
    "-o",
    "--output",
    required=True,
    metavar="OUT.(png|gif|mp4|html)",
    help="the file to write; its suffix picks the format",
  )
  render.add_argument("--frames", type=int, help="render only the first N frames")
  render.add_argument("--fps", type=_rate, default=30.0, help="frame rate of CSV inputs (default 30)")
  render.add_argument(
    "--size", default="1280x720", metavar="WxH", help="GIF/MP4: frame size in pixels (default 1280x720)"
  )
  render.add_argument("--columns", type=int, help="HTML grid columns (default: as many side by side as fit the window)")
  render.add_argument("--title", help="HTML page title")
  render.add_argument(
    "--strip",
    action="store_true",
    help="PNG: filmstrips (a pose every N frames) at the start, middle and end, to see "
    "freezing or trembling at a glance",
  )
  render.add_argument("--every", type=int, default=6, metavar="N", help="--strip: frames between poses (default 6)")
  render.add_argument("--poses", type=int, default=12, help="--strip: poses per row (default 12)")
  render.add_argument("--force", action="store_true", help="overwrite OUT if it exists")
  render.set_defaults(func=_render)


def _add_calibrate_command(sub) -> None:
  """`chorjax calibrate`."""
  cal = sub.add_parser(
    "calibrate",
    help="choose the run's sampling settings on its dancer's takes; the run's default after",
    description="Chooses the run's calibrated sampling settings on its training takes and writes "
    "WORKDIR/calibration.json, the default of sample, eval and live (docs/guides/sampling.md).",
  )
  cal.add_argument("workdir", metavar="WORKDIR", help="a trained run directory")
  cal.add_argument(
    "--data", nargs="+", metavar="PATH_OR_NAME", help="reference takes (default: the run's training takes)"
  )
  cal.add_argument("--frames", type=int, default=1200, help="frames per drawn dancer (default 1200)")
  cal.add_argument(
    "--num",
    type=int,
    help=f"dancers drawn per setting (default {api.CALIBRATION_DANCERS}; {api.LABELLED_DANCERS} for a run with labels)",
  )
  cal.add_argument("--seed", type=_seed, default=0, help="sampling seed (default 0)")
  cal.add_argument(
    "--noise-order",
    type=int,
    metavar="N",
    help=_key_flag("sample.noise_order", "the run's") + "; recorded with the choice",
  )
  cal.add_argument(
    "--pace", type=float, metavar="GAIN", help=_key_flag("sample.pace", "the run's") + "; recorded with the choice"
  )
  cal.add_argument("--force", action="store_true", help="replace an existing calibration.json")
  cal.set_defaults(func=_calibrate)


def _add_report_commands(sub) -> None:
  """`chorjax eval`, `sweep` and `compare`."""
  ev = sub.add_parser("eval", help="held-out likelihood and generation metrics of a trained run")
  ev.add_argument("workdir", metavar="WORKDIR", help="a run directory with checkpoints")
  ev.add_argument(
    "--data",
    nargs="+",
    required=True,
    metavar="PATH_OR_NAME",
    help="real takes to compare with, e.g. cmu94/94_10_skeleton_3d.csv, or `held-out`: the takes of the "
    "run's dataset it did not train on (its validation takes)",
  )
  ev.add_argument("--frames", type=int, default=10_000, help="frames per generated sequence (default 10000)")
  ev.add_argument("--num", type=int, default=4, help="generated sequences (default 4)")
  ev.add_argument(
    "-o",
    "--output",
    metavar="metrics.json",
    help="default: WORKDIR/eval/metrics.json (the first generated dancer goes to sample.npz beside it)",
  )
  ev.add_argument(
    "--seeds",
    type=_seed,
    nargs="+",
    metavar="SEED",
    help="several sampling seeds: --num dancers each, scored together (mean and sd); overrides --seed",
  )
  _add_sampling_args(ev)
  ev.set_defaults(func=_eval)

  _add_calibrate_command(sub)

  me = sub.add_parser("metrics", help="score any motion files against real takes with the eval metrics")
  me.add_argument("motions", nargs="+", metavar="MOTION", help="motion files (.csv, .npz, .bvh, .amc) or folders")
  me.add_argument(
    "--data",
    nargs="+",
    required=True,
    metavar="PATH_OR_NAME",
    help="real reference takes, e.g. cmu94 or a folder (the divisors and the distributions)",
  )
  me.add_argument("-o", "--output", metavar="metrics.json", help="write every key as JSON")
  me.add_argument("--window", type=int, default=60, help="frames per window for FID and novelty (default 60)")
  me.add_argument("--splits", type=int, default=10, help="random halves of the reference for the spreads (default 10)")
  me.add_argument("--seed", type=_seed, default=0, help="seed of the resampling (default 0)")
  me.add_argument("--force", action="store_true", help="overwrite the output if it exists")
  me.set_defaults(func=_metrics)

  sw = sub.add_parser(
    "sweep",
    help="train and evaluate every point of a grid over config keys",
    description=SWEEP_DESCRIPTION,
    epilog=SWEEP_FORMAT,
    formatter_class=argparse.RawDescriptionHelpFormatter,
  )
  sw.add_argument("sweep", metavar="SWEEP.toml", help="the sweep file (format below)")
  sw.add_argument(
    "--shard",
    type=_shard,
    default=(0, 1),
    metavar="I/N",
    help="run only every N-th point, starting at point I (0-based), so N jobs of an array split the sweep "
    "with no coordinator (default 0/1: every point)",
  )
  sw.set_defaults(func=_sweep)

  _add_compare_command(sub)


class _Parser(argparse.ArgumentParser):
  """Usage errors as one line (``--help`` shows the usage), like every other chorjax error."""

  def error(self, message: str):
    self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _add_compare_command(sub) -> None:
  """`chorjax compare`."""
  cmp_ = sub.add_parser(
    "compare",
    help="a markdown report comparing evaluated runs, with plots",
    description="A Markdown report of evaluated runs: runs differing only in train.seed grouped (mean ± sd), a winner"
    " named only beyond that spread, per dataset (docs/guides/sweeps.md).",
  )
  cmp_.add_argument("workdirs", nargs="+", metavar="WORKDIR", help="evaluated run directories (chorjax eval or sweep)")
  cmp_.add_argument("-o", "--output", required=True, metavar="report.md", help="the markdown report to write")
  cmp_.add_argument("--force", action="store_true", help="overwrite the report if it exists")
  cmp_.set_defaults(func=_compare)


def _in_range(low: int, high: int):
  """An argparse type: a whole number within [low, high] (a port, a frame count)."""

  def whole(text: str) -> int:
    try:
      value = int(text)
    except ValueError:
      raise argparse.ArgumentTypeError(f"invalid whole number: {text!r}") from None
    if not low <= value <= high:
      raise argparse.ArgumentTypeError(f"{text}: must be within {low}-{high}")
    return value

  return whole


def _number(low: float, most: float, above: bool = False):
  """An argparse type: a number from ``low`` (``above``: above it) to ``most`` (a frame rate, a scale)."""

  def number(text: str) -> float:
    try:
      value = float(text)
    except ValueError:
      raise argparse.ArgumentTypeError(f"invalid number: {text!r}") from None
    if not (math.isfinite(value) and (low < value if above else low <= value) and value <= most):
      span = f"above {low:g} and at most {most:g}" if above else f"from {low:g} to {most:g}"
      raise argparse.ArgumentTypeError(f"{text}: must be a number {span}")
    return value

  return number


_rate = _number(1.0, 1000.0)  # frames per second, as data.fps allows (render --fps 1e-9 was an internal error)
_seed = _in_range(0, 2**32 - 1)  # a seed JAX takes (calibrate --seed 2**64 + 1 was an internal error)
_scale = _number(1e-6, 1e6)  # a length multiplier (metres to micrometres at most, either way)


def reference_markdown() -> str:
  """Every command and flag as the docs' command-line reference (``docs/cli.md``), from the parser itself:
  ``python -c "from chorjax.cli import reference_markdown as r; print(r(), end='')" > docs/cli.md``."""
  lines = ["# Command-line reference", "", "Generated from `chorjax`'s argument parser.", ""]

  def walk(parser: argparse.ArgumentParser, name: str, summary: str = "") -> None:
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if name != "chorjax" and not subs:
      lines.extend([f"## `{name}`", "", (parser.description or summary).strip(), ""])
      lines.extend(["| flag | what it does |", "| --- | --- |"])
      for action in parser._actions:
        if action.help is argparse.SUPPRESS or isinstance(action, argparse._HelpAction):
          continue
        flag = ", ".join(action.option_strings) or (action.metavar or action.dest)
        text = (action.help or "").replace("|", "\\|")
        lines.append(f"| `{flag}` | {text} |")
      lines.append("")
    for sub in subs:
      said = {a.dest: a.help or "" for a in sub._choices_actions}
      for command, child in sub.choices.items():
        walk(child, f"{name} {command}", said.get(command, ""))

  walk(build_parser(), "chorjax")
  return "\n".join(lines) + "\n"


def build_parser() -> argparse.ArgumentParser:
  parser = _Parser(
    prog="chorjax",
    description=("Learn a dancer's movement language from motion capture and write new dance in it."),
    epilog=(
      "environment: CHORJAX_MALLOC=system keeps glibc's malloc defaults (by default chorjax keeps freed "
      "memory for reuse, which saves page faults on every CPU training step); CHORJAX_COMPILE_CACHE=off keeps no "
      "compiled programs (by default every program XLA compiles is kept in the xla folder of $CHORJAX_CACHE or "
      "~/.cache/chorjax, and later commands load it instead of compiling it again)"
    ),
  )
  sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
  _add_data_commands(sub)
  _add_run_commands(sub)
  _add_report_commands(sub)
  return parser


def _quiet_closed_loop(hook):
  """After a failed checkpoint write or restore, the storage layer's threads still report to orbax's
  event loop, closed by then, and orbax's unfinished read coroutines are closed or end in the read's error;
  Python prints each as an unraisable exception. The failure itself is reported as one line, so only those
  are dropped."""

  def unraisable(info):
    closed_loop = isinstance(info.exc_value, RuntimeError) and str(info.exc_value) == "Event loop is closed"
    code = getattr(info.object, "cr_code", None)  # an orbax coroutine closed unfinished when its read ended
    # (closed, or failed reading an array of a checkpoint that does not fit: the restore has failed already)
    abandoned = isinstance(info.exc_value, GeneratorExit | Exception) and "orbax" in getattr(code, "co_filename", "")
    if not (closed_loop or abandoned):
      hook(info)

  return unraisable


def _signed_axes(argv: list[str]) -> list[str]:
  """``--up-axis -x`` as ``--up-axis=-x``: argparse takes a value that starts with a dash for a flag."""
  out: list[str] = []
  for a in argv:
    if out and out[-1] == "--up-axis" and a in ("-x", "-y", "-z"):
      out[-1] = f"--up-axis={a}"
    else:
      out.append(a)
  return out


def main(argv=None) -> int:
  api.keep_freed_memory()  # before the first JAX computation; see chorjax/runtime.py
  if not getattr(sys.unraisablehook, "chorjax", False):
    sys.unraisablehook = _quiet_closed_loop(sys.unraisablehook)
    sys.unraisablehook.chorjax = True  # type: ignore[attr-defined]
    # (orbax's futures of such a write also end as "Future exception was never retrieved": only orbax
    # runs asyncio in this process, and every failure of its reaches the user as a UserError)
    logging.getLogger("asyncio").setLevel(logging.CRITICAL)
  parser = build_parser()
  args, extra = parser.parse_known_args(_signed_axes(sys.argv[1:] if argv is None else list(argv)))
  api.keep_compiled_programs()  # (not for --help) a program compiled once per machine; see chorjax/runtime.py
  # KEY=VALUE overrides may also follow options (`train c.toml --workdir w model.cell=gru`).
  if extra:
    if hasattr(args, "overrides") and all("=" in e and not e.startswith("-") for e in extra):
      args.overrides = [*args.overrides, *extra]
    else:
      parser.error(f"unrecognized arguments: {' '.join(extra)}")
  for name in ("output", "workdir"):  # '' is no path: the working directory would stand in for it
    if getattr(args, name, None) == "":
      parser.error(f"{'-o' if name == 'output' else name.upper()} '': an empty path")
  try:
    return args.func(args)
  except UserError as e:
    print(f"chorjax: error: {e}", file=sys.stderr)
    return 2
  except Interrupted as e:
    print(f"chorjax: {e}", file=sys.stderr)
    return e.code
  except OSError as e:  # the machine said no (read-only, disk full, a file where a folder should be): one line
    where = f"{e.filename}: " if e.filename else ""
    print(f"chorjax: error: {where}{e.strerror or e}", file=sys.stderr)
    return 2
  except KeyboardInterrupt:
    print("chorjax: interrupted", file=sys.stderr)
    return 130
  except Exception as e:  # the last resort: a bug gets one line that says so, not a traceback
    if os.environ.get("CHORJAX_DEBUG"):
      raise
    what = f"{type(e).__name__}: {str(e).splitlines()[0][:200] if str(e) else ''}"
    print(
      f"chorjax: internal error ({what}): this is a bug in chorjax, please report it; "
      "CHORJAX_DEBUG=1 shows the traceback",
      file=sys.stderr,
    )
    return 1


if __name__ == "__main__":
  sys.exit(main())
