"""Help text lives once, in the config fields' metadata: every key has a short help, `chorjax config keys`
prints them, and the sampling flags' help and defaults come from the keys they set."""

import argparse
import dataclasses

import pytest

from chorjax import cli
from chorjax.config import SampleConfig, key_docs, valid_keys
from chorjax.controls import Controls

MAX_HELP = 160  # characters: one or two lines of a terminal; the reasoning goes to `more` (the docs)


def test_every_config_key_has_a_short_help():
  rows = key_docs()
  assert [r["key"] for r in rows] == valid_keys()
  missing = [r["key"] for r in rows if not r["help"].strip()]
  long = [f"{r['key']} ({len(r['help'])})" for r in rows if len(r["help"]) > MAX_HELP]
  assert not missing, f"keys without help: {missing}"
  assert not long, f"help over {MAX_HELP} characters (move the rest to more=): {long}"


def test_config_keys_prints_every_key_of_a_prefix_with_default_and_help(capsys):
  assert cli.main(["config", "keys", "sample"]) == 0
  out = capsys.readouterr().out
  fields = dataclasses.fields(SampleConfig)
  for f in fields:
    assert f"sample.{f.name} = " in out
  assert "sample.noise_order = 2\n    how many AR(1) filters" in out
  assert "model." not in out
  assert cli.main(["config", "keys", "model.cell"]) == 0
  assert capsys.readouterr().out.splitlines()[0] == 'model.cell = "lnlstm"'
  assert cli.main(["config", "keys", "samples"]) == 2
  assert "did you mean 'sample'" in capsys.readouterr().err


def _sampling_actions() -> dict[str, argparse.Action]:
  """`chorjax sample`'s sampling flags, by the control they set."""
  parser = cli.build_parser()
  sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
  actions = {a.dest: a for a in sub.choices["sample"]._actions}
  return {name: actions[name] for name in Controls.names()}


@pytest.mark.parametrize("name", Controls.names())
def test_a_sampling_flag_says_its_keys_help_and_defers_to_the_run(name):
  action = _sampling_actions()[name]
  help_text = key_docs(f"sample.{name}")[0]["help"]
  assert action.help is not None and action.help.startswith(help_text), (action.help, help_text)
  assert f"sample.{name})" in action.help
  # unset, the flag takes the run's value: its default must not override the key's
  assert action.default in (None, False) and (action.default is None or name == "greedy")


def test_the_help_of_the_noise_keys_says_what_the_code_does():
  smoothing = key_docs("sample.noise_smoothing")[0]
  assert "noise_order" in smoothing["help"] and "two cascaded" not in (smoothing["more"] or "")


def test_the_docs_config_reference_is_generated_from_the_fields():
  """docs/config.md is `chorjax config keys --markdown`: regenerate it when a field changes."""
  from pathlib import Path

  from chorjax.config import reference_markdown

  page = Path(__file__).resolve().parents[1] / "docs" / "config.md"
  assert page.read_text() == reference_markdown(), "docs/config.md is stale: chorjax config keys --markdown > it"
  for row in key_docs():
    assert f"| `{row['key']}` |" in page.read_text()


def _flags_that_set_keys():
  """(command, flag, action, key) for every flag whose help says which config key it stands for."""
  import re

  keys, found = set(valid_keys()), []

  def walk(parser, prefix):
    for action in parser._actions:
      if isinstance(action, argparse._SubParsersAction):
        for name, sub in action.choices.items():
          walk(sub, f"{prefix} {name}".strip())
      m = re.search(r"\(default: [^()]*?([a-z]+\.[a-z_]+)\)(; .*)?$", action.help or "")
      if m and m.group(1) in keys:
        found.append((prefix, action.option_strings[0], action, m.group(1)))

  walk(cli.build_parser(), "")
  return found


def test_every_flag_that_sets_a_key_says_the_keys_help_and_does_not_override_it():
  flags = _flags_that_set_keys()
  commands = {c for c, *_ in flags}
  assert {"sample", "eval", "live", "calibrate", "train"} <= commands, commands
  assert len(flags) >= 14 * 3 + 2 + 4
  for command, flag, action, key in flags:
    assert action.help.startswith(key_docs(key)[0]["help"]), (command, flag)
    assert action.default in (None, False), (command, flag, action.default)  # unset: the run's or config's value


def test_the_docs_command_line_reference_is_generated_and_every_flag_has_help():
  """docs/cli.md is cli.reference_markdown() (regenerate it when a flag changes); no flag without help."""
  from pathlib import Path

  page = (Path(__file__).resolve().parents[1] / "docs" / "cli.md").read_text()
  assert page == cli.reference_markdown(), "docs/cli.md is stale: see cli.reference_markdown's docstring"
  silent = []

  def walk(parser, name):
    for action in parser._actions:
      if isinstance(action, argparse._SubParsersAction):
        for command, child in action.choices.items():
          walk(child, f"{name} {command}")
      elif not isinstance(action, argparse._HelpAction) and not (action.help or "").strip():
        silent.append(f"{name} {'/'.join(action.option_strings) or action.dest}")

  walk(cli.build_parser(), "chorjax")
  assert not silent, f"flags without help: {silent}"
  for command in ("train", "sample", "inbetween", "render", "live", "eval", "calibrate", "metrics", "sweep"):
    assert f"## `chorjax {command}`" in page
