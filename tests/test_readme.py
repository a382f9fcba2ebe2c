"""The Python snippets of README.md and docs/ run as written (one namespace per page)."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def _snippets(page):
  return re.findall(r"```python\n(.*?)```", page.read_text(), flags=re.S)


@pytest.mark.parametrize("page", [p for p in PAGES if _snippets(p)],
                         ids=lambda p: p.relative_to(ROOT).as_posix())
@pytest.mark.slow
def test_python_snippets_run(page, tmp_path, monkeypatch):
  monkeypatch.chdir(tmp_path)  # snippets that write files write them here
  namespace = {}
  for block in _snippets(page):
    exec(compile(block, str(page), "exec"), namespace)  # noqa: S102
