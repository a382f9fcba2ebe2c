"""Sphinx configuration: the pages of docs/ (Markdown, MyST) and the API reference that
autodoc builds from the docstrings (Google style, napoleon).

  python -m sphinx -W --keep-going -b html docs docs/_build/html
"""

import inspect
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)  # the package of this checkout, installed or not

import mfsample  # noqa: E402

project = "mfsample"
author = "the mfsample authors"
copyright = "the mfsample authors, Apache 2.0"  # noqa: A001 (Sphinx's name)
release = version = mfsample.__version__

extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.napoleon",
              "sphinx.ext.mathjax"]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build"]

# The pages link to one another as files (`training.md#cost`): MyST resolves them, and the
# headings' anchors, as GitHub does.
myst_heading_anchors = 4
myst_enable_extensions = ["dollarmath"]

# Docstrings name code in single backticks (Markdown's habit): shown as code.
default_role = "literal"

autodoc_member_order = "bysource"
autodoc_default_options = {"members": True, "show-inheritance": False}
autodoc_typehints = "signature"
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_rtype = False

html_theme = "alabaster"
html_title = f"mfsample {release}"


def _skip_namedtuple_fields(app, what, name, obj, skip, options):
  """A NamedTuple's fields are described by its docstring's "Attributes:" section: their
  own docstrings ("Alias for field number 0") would describe each a second time."""
  if (getattr(obj, "__doc__", None) or "").startswith("Alias for field number"):
    return True
  return None


def _no_type_docstrings(app, what, name, obj, options, lines):
  """A constant's docstring is its reference entry's text, not its type's (`tuple`, `dict`
  and `int` have docstrings of their own, which autodoc would otherwise show)."""
  words = lambda text: " ".join(text.split())
  own = inspect.getdoc(type(obj))
  if what == "data" and own and words("\n".join(lines)) == words(own):
    lines.clear()


def setup(app):
  app.connect("autodoc-skip-member", _skip_namedtuple_fields)
  app.connect("autodoc-process-docstring", _no_type_docstrings)
