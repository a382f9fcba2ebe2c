"""`benchmarks/aim_gaps.py`: the README's figure of where the aim stands reads every record it
names (committed under results/), so a renamed or incomplete record fails here, not in a
reader's rerun."""

import json
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_every_gap_of_the_aim_figure_comes_from_its_committed_record(tmp_path):
  out = tmp_path / "aim_gaps.json"
  env = {**os.environ, "PYTHONPATH": str(REPO), "MPLBACKEND": "Agg"}
  proc = subprocess.run([sys.executable, "benchmarks/aim_gaps.py", f"--out={out}"], cwd=REPO,
                        env=env, capture_output=True, text=True, timeout=300)
  assert proc.returncode == 0, proc.stderr[-3000:]
  gaps = json.loads(out.read_text())["gaps"]
  assert {g["comparison"] for g in gaps} == {
      "Ours (Sel.) - Farthest Point", "Ours (Sel.) - FisherRF",
      "Ours (Opt. Sel.) - Ours (Sel.)", "Ours (Opt. Best) - Ours (Sel.)"}
  for g in gaps:
    # Every protocol was run with at least eight seeds, so each gap has a standard error.
    assert len(g["seeds"]) >= 8 and g["sem"] > 0, g
    assert abs(sum(g["values"]) / len(g["values"]) - g["mean"]) < 1e-9
    assert g["fixed_in_advance"] in ("", "all") or g["fixed_in_advance"].startswith("seeds ")
  # The table printed is the one written.
  assert proc.stdout.count("| Ours (") == len(gaps)
