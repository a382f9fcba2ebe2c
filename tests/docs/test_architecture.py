"""docs/architecture.md stays true: every module listed, each layer importing only upwards,
configs read by the jobs alone."""

import ast
import pathlib
import re
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "mfsample"
LAYERS = ("base", "core", "methods", "data", "training", "jobs", "apps")


def _table():
  """{module path: layer} of the page's module table ("-" for re-exporting __init__ files)."""
  rows = re.findall(r"^\| `(mfsample/[\w/]+\.py)` \| ([\w-]+) \|",
                    (ROOT / "docs" / "architecture.md").read_text(), re.MULTILINE)
  return dict(rows)


def _module_file(dotted):
  """The file of a dotted module name, or None."""
  path = ROOT.joinpath(*dotted.split("."))
  if path.with_suffix(".py").is_file():
    return path.with_suffix(".py")
  if (path / "__init__.py").is_file():
    return path / "__init__.py"
  return None


def _reexports(init_file):
  """{name: defining module file} of the `from mfsample.x import name` lines of an __init__."""
  out = {}
  for node in ast.walk(ast.parse(init_file.read_text())):
    if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("mfsample"):
      for alias in node.names:
        target = _module_file(f"{node.module}.{alias.name}") or _module_file(node.module)
        out[alias.asname or alias.name] = target
  return out


def _imported_files(path):
  """The package files a module imports (anywhere in it, functions included), with a
  package's re-exported names followed to the module that defines them."""
  files = set()
  for node in ast.walk(ast.parse(path.read_text())):
    if isinstance(node, ast.Import):
      names = [(a.name, None) for a in node.names]
    elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
      names = [(node.module, a.name) for a in node.names]
    else:
      continue
    for module, name in names:
      if not module.startswith("mfsample"):
        continue
      if name is not None and _module_file(f"{module}.{name}") is not None:
        files.add(_module_file(f"{module}.{name}"))
        continue
      target = _module_file(module)
      if target is not None and target.name == "__init__.py" and name is not None:
        target = _reexports(target).get(name, target)
      if target is not None:
        files.add(target)
  return files


def test_the_page_lists_every_module_and_only_those():
  listed = set(_table())
  present = {str(p.relative_to(ROOT)) for p in PACKAGE.rglob("*.py")}
  assert listed == present, (f"not on docs/architecture.md: {sorted(present - listed)}; "
                             f"listed but absent: {sorted(listed - present)}")


def test_layers_import_only_downwards():
  table = _table()
  assert set(table.values()) <= set(LAYERS) | {"-"}, set(table.values())
  wrong = []
  for module, layer in table.items():
    if layer == "-":
      continue
    for target in _imported_files(ROOT / module):
      other = table.get(str(target.relative_to(ROOT)))
      if other not in (None, "-") and LAYERS.index(other) > LAYERS.index(layer):
        wrong.append(f"{module} ({layer}) imports {target.relative_to(ROOT)} ({other})")
  assert not wrong, "\n".join(wrong)


def test_nothing_below_the_jobs_reads_a_config():
  """Config at the edge: only the jobs layer and above import ml_collections."""
  table = _table()
  below = {m for m, layer in table.items() if layer not in ("-", "jobs", "apps")}
  wrong = []
  for module in sorted(below):
    for node in ast.walk(ast.parse((ROOT / module).read_text())):
      names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
          [node.module] if isinstance(node, ast.ImportFrom) and node.module else [])
      if any(n == "ml_collections" or n.startswith("ml_collections.") for n in names):
        wrong.append(f"{module} ({table[module]})")
  assert not wrong, "below the jobs layer, these import ml_collections: " + ", ".join(wrong)


def test_the_library_imports_no_job():
  """`import mfsample` (the functional API) loads neither ml_collections nor a job module."""
  code = ("import sys, mfsample, mfsample.train, mfsample.lighting, mfsample.data, "
          "mfsample.planning; bad = sorted(m for m in sys.modules if m.startswith("
          "'ml_collections') or m in ('mfsample.jobs', 'mfsample.config_blocks')); "
          "print(bad); sys.exit(1 if bad else 0)")
  out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       cwd=ROOT, timeout=300, check=False)
  assert out.returncode == 0, out.stdout + out.stderr
