"""The README's Python snippets run as written (one namespace, top to bottom)."""

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_python_snippets_run():
  blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
  assert len(blocks) >= 2, "the README lost its API snippets"
  namespace = {}
  for block in blocks:
    exec(compile(block, str(README), "exec"), namespace)  # noqa: S102
  assert namespace["out"].rgb.shape == (200, 200, 3)
  assert float(namespace["u"].value) > 0.0
