"""The notebooks run top to bottom from their own folder, at a tiny size."""

from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"


@pytest.mark.slow
@pytest.mark.parametrize("name,expected", [("quickstart.ipynb", "optimised:"),
                                           ("lighting.ipynb", "relit test views: PSNR")])
def test_notebook_executes(monkeypatch, name, expected):
  monkeypatch.setenv("MFSAMPLE_NOTEBOOK_TINY", "1")
  nb = nbformat.read(NOTEBOOKS / name, as_version=4)
  client = nbclient.NotebookClient(nb, timeout=300, kernel_name="python3",
                                   resources={"metadata": {"path": str(NOTEBOOKS)}})
  client.execute()
  outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
  assert not [o for o in outputs if o.get("output_type") == "error"]
  text = "".join(o.get("text", "") for o in outputs if o.get("output_type") == "stream")
  assert expected in text
