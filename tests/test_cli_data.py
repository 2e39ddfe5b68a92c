"""`chorjax data info` / `data plot` on the bundled takes, through the real console script."""

import re
import subprocess
import sys

from chorjax import cli
from chorjax.data.dataset import bundled_path


def run(*args):
  return subprocess.run([sys.executable, "-m", "chorjax.cli", *args], capture_output=True, text=True)


def test_data_info_lists_all_takes_with_rigid_bones():
  r = run("data", "info", "cmu94")
  assert r.returncode == 0, r.stderr
  rows = [l for l in r.stdout.splitlines() if "94_" in l]
  assert len(rows) == 10
  for row in rows:
    median_cv = float(re.findall(r"([\d.]+)%", row)[0])
    assert 0 < median_cv <= 3.0


def test_data_info_bad_input_is_one_line_exit_2(tmp_path):
  r = run("data", "info", str(tmp_path / "missing.csv"))
  assert r.returncode == 2
  assert r.stderr.strip().count("\n") == 0 and "missing.csv" in r.stderr and "Traceback" not in r.stderr


def test_data_plot_writes_a_png(tmp_path):
  out = tmp_path / "p.png"
  take = bundled_path("cmu94") / "94_01_skeleton_3d.csv"
  assert cli.main(["data", "plot", str(take), "-o", str(out)]) == 0
  assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 10_000


def test_every_flag_of_every_subcommand_has_help_and_states_its_default():
  import argparse

  from chorjax.cli import build_parser

  missing = []
  has_default = lambda a: (
    bool(a.option_strings) and a.default is not None and a.default is not False and a.default != argparse.SUPPRESS
  )

  def walk(parser, name):
    for action in parser._actions:
      if isinstance(action, argparse._SubParsersAction):
        for sub, p in action.choices.items():
          walk(p, f"{name} {sub}")
      elif not isinstance(action, argparse._HelpAction) and not action.help:
        missing.append(f"{name} {'/'.join(action.option_strings) or action.dest}")
      elif has_default(action) and "default" not in action.help:  # a flag with a default says it
        missing.append(f"{name} {'/'.join(action.option_strings)} (default {action.default!r} not stated)")

  walk(build_parser(), "chorjax")
  assert not missing
