"""An interactive capture planner in the browser: a job's workdir shown with viser.

`experiments/viewer.py --workdir=...` (docs/viewer.md). `runs` reads what the your-data,
camera-planning and light-planning jobs write; `models` reads and renders their models;
`rounds` is what camera planning writes for it; `app` is the server (needs the optional
extra `viewer`, which brings viser).
"""

from mfsample.viewer.runs import (
    KINDS,
    NoRunYet,
    Proposal,
    Run,
    RunError,
    Step,
    default_step,
    open_run,
)

__all__ = ["KINDS", "NoRunYet", "Proposal", "Run", "RunError", "Step", "default_step",
           "open_run"]
