"""The guides' examples work as written: every `.venv/bin/chorjax` line of the ``bash`` blocks of docs/ runs,
in page order, on toy sizes (a file of its own so that its worker runs beside the README's)."""

import re

from test_docs import FIRST_HOUR, GUIDES, ROOT, commands, run_documented


def test_the_guides_have_examples_and_no_bare_chorjax_command():
  pages = {page.name: commands(page) for page in GUIDES}
  assert sum(map(len, pages.values())) >= 15, pages
  for page in GUIDES:
    for block in re.findall(r"```bash\n(.*?)```", page.read_text(), flags=re.S):
      for line in block.splitlines():
        assert not line.startswith("chorjax "), f"{page.name} runs a bare chorjax: {line}"


def test_every_guide_command_runs(tmp_path, monkeypatch):
  """The guides the first hour does not run (test_docs runs own-data and export after the README, in one clone)."""
  rest = [page for page in GUIDES if str(page.relative_to(ROOT)) not in FIRST_HOUR]
  assert len(rest) == len(GUIDES) - 2
  monkeypatch.chdir(tmp_path)
  run_documented([line for page in rest for line in commands(page)], tmp_path)
