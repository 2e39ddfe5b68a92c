"""Help text lives once, in the config fields' metadata: every key has a short help, `chorjax config keys`
prints them, and the sampling flags' help and defaults come from the keys they set."""

import argparse
import dataclasses

import pytest

from chorjax import cli
from chorjax.config import key_docs, valid_keys
from chorjax.sampling.controls import Controls
from chorjax.sampling.table import DECODING, FLAGGED
from chorjax.sections import SampleConfig

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


def _sample_actions() -> dict[str, argparse.Action]:
  """`chorjax sample`'s flags, by what they set."""
  parser = cli.build_parser()
  sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
  return {a.dest: a for a in sub.choices["sample"]._actions}


def _sampling_actions() -> dict[str, argparse.Action]:
  """`chorjax sample`'s sampling flags, by the control they set."""
  return {name: _sample_actions()[name] for name in FLAGGED}


def test_the_draw_has_three_flags_and_the_opt_ins_one_key_value_flag():
  """`chorjax sample --help`: three draw flags (and --plain) beside decoding's; every other control is named by
  the help of --set sample.KEY=VALUE, and has no flag of its own."""
  actions = _sample_actions()
  draw = [n for n in Controls.names() if n in actions and n not in DECODING]
  assert draw == ["sigma_temperature", "pace", "clamp"]
  opt_ins = [n for n in Controls.names() if n not in FLAGGED]
  assert opt_ins and all(n not in actions and n in actions["set"].help for n in opt_ins)


@pytest.mark.parametrize("name", FLAGGED)
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
  assert len(flags) >= len(FLAGGED) * 4 + 2 + 4  # sample, eval, export and live each; calibrate's; train's
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


ROOT = __import__("pathlib").Path(__file__).resolve().parents[1]


def _walk_flags():
  """(command, action) for every flag and argument of every command."""
  found = []

  def walk(parser, name):
    for action in parser._actions:
      if isinstance(action, argparse._SubParsersAction):
        for command, child in action.choices.items():
          walk(child, f"{name} {command}".strip())
      elif not isinstance(action, argparse._HelpAction):
        found.append((name, action))

  walk(cli.build_parser(), "")
  return found


def test_the_site_builds_strictly_offline_with_every_flag_key_metric_and_api_name(tmp_path):
  """mkdocs (material + mkdocstrings) in strict mode: a warning, a broken link or an unresolved docstring fails
  the build. Its reference pages hold every flag and config key with help, every metric, the API's names."""
  import html
  import os
  import subprocess
  import sys

  from chorjax.evaluation.reports import metric_keys

  site = tmp_path / "site"
  env = {
    **os.environ,
    "NO_MKDOCS_2_WARNING": "1",
    "no_proxy": "*",
    "http_proxy": "http://0.0.0.0:9",
    "https_proxy": "http://0.0.0.0:9",
  }
  out = subprocess.run(
    [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(ROOT / "mkdocs.yml"), "-d", str(site)],
    capture_output=True,
    text=True,
    env=env,
    cwd=ROOT,
  )
  assert out.returncode == 0, out.stderr[-3000:]
  assert "WARNING" not in out.stderr, out.stderr[-3000:]
  page = lambda name: html.unescape((site / name / "index.html").read_text())
  cli_page, keys_page, metrics_page, api_page = page("cli"), page("config"), page("metrics"), page("api")
  for command, action in _walk_flags():
    assert f"chorjax {command}" in cli_page, command
    shown = ", ".join(action.option_strings) or action.dest.upper()
    assert action.help and action.help.strip(), (command, shown)
    names = action.option_strings or [action.metavar or action.dest.upper()]
    assert any(s in cli_page for s in names), (command, shown)
  for row in key_docs():
    assert row["key"] in keys_page and row["help"].strip(), row["key"]
    assert html.unescape(row["help"]).split("`")[0][:40] in keys_page, row["key"]
  missing = [k for k in metric_keys() if k not in metrics_page]
  assert not missing, f"metrics without a definition on the metrics page: {missing}"
  names = ("train", "load_run", "read_motion", "load_dataset", "score", "Motion.write", "Motion.show", "Run.sample")
  for name in names:
    assert f'id="chorjax.api.{name}"' in api_page, name


# Development-log wording that has no place in what a user reads: work periods, lent or borrowed machines,
# "the development machine", issue numbers of a tracker the reader cannot see, dates as history markers
# (history goes to CHANGELOG.md). Keep this list current.
DEV_LOG = (
  r"\b(work )?(session|round|period)s? \d+\b",
  r"\bwork periods?\b",
  r"\blent\b",
  r"\bborrowed\b",
  r"\bdevelopment machine\b",
  r"\bissues? #?\d+\b",
  r"\b(until|since|before) 20\d\d-\d\d-\d\d\b",
)


def _user_facing_texts():
  from chorjax.config import reference_markdown

  pages = [ROOT / "README.md", ROOT / "BENCHMARKS.md", *ROOT.glob("docs/**/*.md"), *ROOT.glob("configs/*.toml")]
  pages += [*ROOT.glob("experiments/**/README.md"), *ROOT.glob("experiments/*/*.toml")]
  texts = {str(p.relative_to(ROOT)): p.read_text() for p in pages}
  texts["chorjax --help texts"] = cli.reference_markdown()
  texts["config help texts"] = reference_markdown()
  return texts


@pytest.mark.parametrize("pattern", DEV_LOG)
def test_no_development_log_wording_in_docs_or_help(pattern):
  import re

  hits = [
    f"{name}: {m.group(0)!r}" for name, text in _user_facing_texts().items() for m in re.finditer(pattern, text, re.I)
  ]
  assert not hits, hits[:20]


def test_the_wording_check_catches_what_it_names():
  import re

  for bad in ("in session 25", "a lent H100", "the development machine", "see issue 35", "until 2026-11-27"):
    assert any(re.search(p, bad, re.I) for p in DEV_LOG), bad
  for fine in ("a one-line error", "the sessions of a dancer", "lentil", "measured on 2026-11-27"):
    assert not any(re.search(p, fine, re.I) for p in DEV_LOG), fine


MAX_DESCRIPTION = 200  # characters: a command's description is one or two lines; the guides hold the rest


def test_every_command_description_and_flag_help_is_one_or_two_lines():
  long = []

  def walk(parser, name):
    if len(parser.description or "") > MAX_DESCRIPTION:
      long.append(f"{name} description ({len(parser.description)})")
    for action in parser._actions:
      if isinstance(action, argparse._SubParsersAction):
        for command, child in action.choices.items():
          walk(child, f"{name} {command}")

  walk(cli.build_parser(), "chorjax")
  long += [f"chorjax {c} {a.option_strings} ({len(a.help)})" for c, a in _walk_flags() if len(a.help) > MAX_DESCRIPTION]
  assert not long, long


def test_the_licence_is_in_the_package_metadata_and_the_citation_is_valid_cff():
  import importlib.metadata
  import subprocess
  import sys
  from pathlib import Path

  meta = importlib.metadata.metadata("chorjax")
  assert meta["License-Expression"] == "Apache-2.0" and "LICENSE" in meta.get_all("License-File")
  assert (ROOT / "LICENSE").read_text().lstrip().startswith("Apache License")
  cffconvert = Path(sys.executable).parent / "cffconvert"
  command = [str(cffconvert), "--validate", "-i", str(ROOT / "CITATION.cff")]
  out = subprocess.run(command, capture_output=True, text=True)
  assert out.returncode == 0 and "are valid" in out.stdout, out.stdout + out.stderr
  citation = (ROOT / "CITATION.cff").read_text()
  assert "chor-rnn" in citation and "Crnkovic-Friis" in citation
