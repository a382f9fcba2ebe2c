"""The notebooks run top to bottom at a tiny size.

Their code cells run in this process, one namespace per notebook (as a kernel would run
them), so they reuse the compilations of the rest of the suite instead of paying for a
fresh kernel's; figures go to matplotlib's non-interactive backend.
"""

from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
matplotlib = pytest.importorskip("matplotlib")

NOTEBOOKS = Path(__file__).resolve().parents[2] / "notebooks"


@pytest.mark.slow
@pytest.mark.parametrize("name,expected", [("quickstart.ipynb", "optimised:"),
                                           ("lighting.ipynb", "relit test views: PSNR")])
def test_notebook_runs(monkeypatch, tmp_path, capsys, name, expected):
  matplotlib.use("Agg")
  import matplotlib.pyplot as plt

  monkeypatch.setenv("MFSAMPLE_NOTEBOOK_TINY", "1")
  monkeypatch.chdir(tmp_path)  # files a notebook writes land here
  nb = nbformat.read(NOTEBOOKS / name, as_version=4)
  cells = [c.source for c in nb.cells if c.cell_type == "code"]
  assert not [s for s in cells if s.lstrip().startswith(("%", "!"))], "IPython-only syntax"
  namespace = {"__name__": "__main__"}
  for i, source in enumerate(cells):
    exec(compile(source, f"{name}, code cell {i}", "exec"), namespace)  # noqa: S102
  plt.close("all")
  assert expected in capsys.readouterr().out
