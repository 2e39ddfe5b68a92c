"""The ``chorjax`` command line: one small function per subcommand.

User errors print one line (``chorjax: error: ...``) and exit with code 2, without a traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import logging
import os
import sys
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

from rich.console import Console

from chorjax import api
from chorjax.api import Interrupted, UserError
from chorjax.cli_parser import build_parser


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
  print("\n".join(api.metric_lines(result, ("heldout_loss", *api.metric_keys()))))
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
  print("\n".join(api.metric_lines(result, api.metric_keys())))
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
  """The sampling flags and ``--set sample.KEY=VALUE`` keys given on the command line, each with the flag that
  gave it (``Controls.resolve`` checks them as the same keys are in a config file and names the flag; unset
  ones are None: the run's calibration, then its config)."""
  given = {k: getattr(args, k, None) for k in api.Controls.names()}
  given = {k: None if v is None else api.Given(v, f"--{k.replace('_', '-')}") for k, v in given.items()}
  for text in getattr(args, "set", []):
    key, value = api.parse_override(text)
    section, _, name = key.partition(".")
    if section != "sample" or name not in given:
      raise UserError(f"--set {text}: expected sample.KEY=VALUE, KEY a sampling control ({', '.join(given)})")
    if given[name] is not None:
      raise UserError(f"--set {text}: sample.{name} is given twice")
    given[name] = api.Given(value, f"--set sample.{name}")
  if getattr(args, "plain", False):
    both = [v.where for k, v in given.items() if k in api.PLAIN and v is not None]
    if both:
      raise UserError(f"--plain is the model's own draw: not with {both[0]}")
    given.update(api.PLAIN)
  return given


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


HANDLERS = {
  "data_convert": _data_convert,
  "data_info": _data_info,
  "data_plot": _data_plot,
  "data_check": _data_check,
  "config_show": _config_show,
  "config_keys": _config_keys,
  "train": _train,
  "sample": _sample,
  "export": _export,
  "blender_addon": _blender_addon,
  "inbetween": _inbetween,
  "live": _live,
  "render": _render,
  "calibrate": _calibrate,
  "eval": _eval,
  "metrics": _metrics,
  "sweep": _sweep,
  "compare": _compare,
}  # a subcommand's handler by the name its parser gives (cli_parser)


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
    return HANDLERS[args.func](args)
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
