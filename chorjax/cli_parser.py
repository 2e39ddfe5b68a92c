"""The ``chorjax`` command line's parser: every subcommand, its flags and their help, and the argument types that
check a flag's value as it is read. Each subcommand names its handler in ``chorjax.cli`` (``func``)."""

from __future__ import annotations

import argparse
import math

from chorjax import api


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
  """Sampling controls shared by `sample`, `eval`, `export` and `live`; unset ones come from the run's
  calibration.json (`chorjax calibrate`), else its [sample] config. The help lists the draw's apart from
  decoding's; the controls without a flag of their own are opt-ins, set by `--set sample.KEY=VALUE`."""
  groups = {
    "draw": p.add_argument_group("draw", "how each frame is drawn (sampling controls)"),
    "decoding": p.add_argument_group("decoding", "how drawn features become joints"),
  }
  for name in api.FLAGGED:
    record = api.RECORDS[name]
    flag, group = f"--{name.replace('_', '-')}", groups[record.role]
    if record.metavar:  # a number: its type is its default's
      kind = type(getattr(api.Controls(), name))
      group.add_argument(flag, type=kind, metavar=record.metavar, help=_control_help(name))
    else:
      group.add_argument(flag, action=argparse.BooleanOptionalAction, help=_control_help(name))
  opt_in = ", ".join(n for n in api.RECORDS if n not in api.FLAGGED)
  p.add_argument_group("opt-in", "draw controls the default draw leaves off").add_argument(
    "--set",
    action="append",
    default=[],
    metavar="sample.KEY=VALUE",
    help=f"a [sample] key for this draw (repeatable; `chorjax config keys sample`; default: none, the run's): {opt_in}",
  )
  groups["draw"].add_argument(
    "--plain",
    action="store_true",
    help="the model's own draw: temperatures 1 and every other draw control off; decoding (rigid bones, feet) "
    "as the run's",
  )
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
  conv.set_defaults(func="data_convert")


def _add_data_commands(sub) -> None:
  """`chorjax data info|plot|convert` and `chorjax config show`."""
  data = sub.add_parser("data", help="inspect and plot motion data")
  dsub = data.add_subparsers(dest="data_command", required=True, metavar="DATA_COMMAND")
  info = dsub.add_parser("info", help="per take: frames, joints, fps, value ranges, bone lengths and CV")
  info.add_argument(
    "inputs", nargs="+", metavar="PATH_OR_NAME", help="a bundled dataset (cmu94), a folder of takes, or a file"
  )
  info.set_defaults(func="data_info")
  plot = dsub.add_parser("plot", help="pelvis and end joints over time (first 200 frames, the rest) as PNG")
  plot.add_argument("input", metavar="PATH", help="one motion file")
  plot.add_argument("-o", "--output", required=True, metavar="FILE.png", help="the PNG to write (required)")
  plot.add_argument("--split", type=_in_range(1, 10**7), default=200, help="frames in the first row (default 200)")
  plot.set_defaults(func="data_plot")
  check = dsub.add_parser(
    "check",
    help="per take and for the set: frames, rate, units and up axis (with the evidence), skeleton and mapping, "
    "bone stability, gaps, root jumps, the floor; the config keys to use; exit 2 on a fatal problem",
  )
  check.add_argument("inputs", nargs="+", metavar="PATH", help="motion files, folders or a bundled dataset name")
  check.add_argument("--joint-map", metavar="MAP.toml", help="map skeletons by this file (default: automatic)")
  check.add_argument("--fps", type=_rate, default=30.0, help="frame rate of CSV inputs (default 30)")
  check.set_defaults(func="data_check")
  _add_convert_command(dsub)

  config = sub.add_parser("config", help="inspect run configs")
  csub = config.add_subparsers(dest="config_command", required=True, metavar="CONFIG_COMMAND")
  show = csub.add_parser("show", help="print the resolved config (file + overrides) as TOML")
  show.add_argument("config", nargs="?", metavar="CONFIG", help="a TOML config (default: the built-in defaults)")
  show.add_argument("overrides", nargs="*", metavar="KEY=VALUE", help="dotted overrides, e.g. model.cell=gru")
  show.set_defaults(func="config_show")
  keys = csub.add_parser("keys", help="every config key with its default and help (PREFIX: a section or key)")
  keys.add_argument("prefix", nargs="?", default="", metavar="PREFIX", help="e.g. sample or model.cell (default: all)")
  keys.add_argument("--more", action="store_true", help="also the longer notes some keys carry")
  keys.add_argument("--markdown", action="store_true", help="every key as the docs' reference page (docs/config.md)")
  keys.set_defaults(func="config_keys")


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
  train.set_defaults(func="train")

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
  sample.set_defaults(func="sample")

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
  p.set_defaults(func="export")


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
  p.set_defaults(func="blender_addon")


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
  p.set_defaults(func="inbetween")


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
  live.set_defaults(func="live")


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
  readable = ", ".join(api.formats.suffixes("read"))  # asked as the parser is built: a registered format counts
  render.add_argument(
    "inputs",
    nargs="+",
    metavar="INPUT",
    help=f"motion files ({readable}), folders or cmu94",
  )
  render.add_argument(
    "-o",
    "--output",
    required=True,
    metavar="OUT",
    help=f"the file to write; its suffix picks the format: {api.formats.listed('draw')}",
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
  render.set_defaults(func="render")


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
  frames = f"frames per drawn dancer (default {api.CALIBRATION_FRAMES}; {api.CARRIED_FRAMES} for a carried MDN)"
  num = f"dancers drawn per setting (default {api.CALIBRATION_DANCERS}; {api.LABELLED_DANCERS} for a run with labels)"
  cal.add_argument("--frames", type=int, help=frames)
  cal.add_argument("--num", type=int, help=num)
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
  cal.set_defaults(func="calibrate")


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
    help="default: WORKDIR/eval/metrics.json; its first dancer beside it (sample.npz; NAME.sample.npz for NAME.json)",
  )
  ev.add_argument(
    "--seeds",
    type=_seed,
    nargs="+",
    metavar="SEED",
    help="several sampling seeds: --num dancers each, scored together (mean and sd); overrides --seed",
  )
  _add_sampling_args(ev)
  ev.set_defaults(func="eval")

  _add_calibrate_command(sub)

  me = sub.add_parser("metrics", help="score any motion files against real takes with the eval metrics")
  readable = ", ".join(api.formats.suffixes("read"))
  me.add_argument("motions", nargs="+", metavar="MOTION", help=f"motion files ({readable}) or folders")
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
  me.set_defaults(func="metrics")

  sw = sub.add_parser(
    "sweep",
    help="train and evaluate every point of a grid over config keys",
    description=api.SWEEP_DESCRIPTION,
    epilog=api.SWEEP_FORMAT,
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
  sw.set_defaults(func="sweep")

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
  cmp_.set_defaults(func="compare")


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
