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


def _slug(heading):
  """GitHub's anchor for a markdown heading: lower case, punctuation dropped, spaces to -."""
  return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def test_documentation_links_resolve():
  """Every relative link and image of the README and docs/ names a file that exists, every
  #anchor a heading of its target, and every results/ path they cite a committed file."""
  root = README.parent
  pages = [README, *sorted((root / "docs").glob("*.md"))]
  assert len(pages) > 1, "docs/ lost its pages"
  broken = []
  for page in pages:
    for target in re.findall(r"\]\(([^)\s]+)\)", page.read_text()):
      if re.match(r"[a-z]+://", target):
        continue
      path, _, anchor = target.partition("#")
      file = (page.parent / path).resolve() if path else page
      if not file.exists():
        broken.append(f"{page.name}: {target} (no such file)")
      elif anchor:
        headings = re.findall(r"^#+ (.*)$", file.read_text(), flags=re.M)
        if anchor not in {_slug(h) for h in headings}:
          broken.append(f"{page.name}: {target} (no such heading)")
  # Result files named in the text (commands' outputs, tables' sources) are committed.
  for page in pages:
    for name in set(re.findall(r"(?<![\w/.])(results/[\w\-./*]+)", page.read_text())):
      if not list(root.glob(name.rstrip("."))):
        broken.append(f"{page.name}: {name} (not in the repository)")
  assert not broken, broken
