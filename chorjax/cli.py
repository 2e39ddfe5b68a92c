"""The ``chorjax`` command line: one small function per subcommand.

User errors print one line (``chorjax: error: ...``) and exit with code 2, without a traceback.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from chorjax.errors import UserError


def _data_info(args) -> int:
  import numpy as np
  from rich.console import Console
  from rich.table import Table
  from chorjax.data.dataset import read_takes
  from chorjax.data.motion import bone_length_cv

  motions = read_takes(args.inputs)
  table = Table(title="takes", show_lines=False)
  for col in ("take", "frames", "joints", "fps", "x range", "y range", "z range", "bone len (mean)",
              "bone CV median", "bone CV max"):
    table.add_column(col, justify="left" if col == "take" else "right")
  for m in motions:
    lo, hi = m.positions.min(axis=(0, 1)), m.positions.max(axis=(0, 1))
    cv = bone_length_cv(m.positions, m.skeleton) * 100
    table.add_row(m.name, str(m.num_frames), str(m.skeleton.num_joints), f"{m.fps:g}",
                  *[f"{lo[i]:.4g}..{hi[i]:.4g}" for i in range(3)],
                  f"{m.bone_lengths().mean():.4g}", f"{np.median(cv):.2f}%", f"{cv.max():.2f}%")
  Console(width=200).print(table)
  return 0


def _data_plot(args) -> int:
  from chorjax.data.dataset import read_takes
  from chorjax.render.plot import plot_trajectories

  motions = read_takes([args.input])
  if len(motions) != 1:
    raise UserError(f"{args.input}: holds {len(motions)} takes; plot one file at a time")
  out = plot_trajectories(motions[0], args.output, split=args.split)
  print(f"wrote {out}")
  return 0


def build_parser() -> argparse.ArgumentParser:
  parser = argparse.ArgumentParser(prog="chorjax", description=(
      "Learn a dancer's movement language from motion capture and write new dance in it."))
  sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

  data = sub.add_parser("data", help="inspect and plot motion data")
  dsub = data.add_subparsers(dest="data_command", required=True, metavar="DATA_COMMAND")
  info = dsub.add_parser("info", help="per take: frames, joints, fps, value ranges, bone lengths and CV")
  info.add_argument("inputs", nargs="+", metavar="PATH_OR_NAME",
                    help="a bundled dataset (cmu94), a folder of takes, or a file")
  info.set_defaults(func=_data_info)
  plot = dsub.add_parser("plot", help="pelvis and end joints over time (first 200 frames, the rest) as PNG")
  plot.add_argument("input", metavar="PATH", help="one motion file")
  plot.add_argument("-o", "--output", required=True, metavar="FILE.png")
  plot.add_argument("--split", type=int, default=200, help="frames in the first row (default 200)")
  plot.set_defaults(func=_data_plot)
  return parser


def main(argv=None) -> int:
  parser = build_parser()
  args = parser.parse_args(argv)
  try:
    return args.func(args)
  except UserError as e:
    print(f"chorjax: error: {e}", file=sys.stderr)
    return 2
  except KeyboardInterrupt:
    print("chorjax: interrupted", file=sys.stderr)
    return 130


if __name__ == "__main__":
  sys.exit(main())
