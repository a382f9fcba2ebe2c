"""The viewer's command line: `mfsample viewer --workdir=DIR` (`experiments/viewer.py`).

  mfsample viewer --workdir=workdirs/camera_planning
  mfsample viewer --workdir=workdirs/camera_planning \
      --screenshot=workdirs/camera_planning/viewer.png

Opens the workdir of the next-views job, camera planning or light planning, finished or
running, and prints the address to open. Binds to this machine only (127.0.0.1) unless
--host says otherwise; a running job's new steps appear as it writes them, a workdir no job
has written yet is waited for, and damaged files are named in the panel (docs/viewer.md).

Flags: --workdir (required), --host (127.0.0.1), --port (8080; 0: any free port),
--poll_seconds (2.0), --screenshot=PATH (save a PNG of the page as headless Chromium shows
it, its folder created, and exit).
"""

import sys


def main():
  """The absl entry point: defines the viewer's flags and serves (or screenshots) the
  workdir; errors are one line and exit code 1."""
  from absl import app, flags

  workdir = flags.DEFINE_string("workdir", None, "Workdir of a your-data, camera-planning or "
                                "light-planning job.")
  host = flags.DEFINE_string("host", "127.0.0.1", "Address to listen on: 127.0.0.1 (this "
                             "machine only); 0.0.0.0 for every interface (anyone who can reach "
                             "this machine can then see the scene: there is no login).")
  port = flags.DEFINE_integer("port", 8080, "Port to listen on (0: any free port).")
  poll = flags.DEFINE_float("poll_seconds", 2.0, "How often the workdir is read again.")
  shot = flags.DEFINE_string("screenshot", None, "Save a PNG of the page as headless "
                             "Chromium shows it at this path (its folder created), and "
                             "exit.")
  flags.mark_flags_as_required(["workdir"])

  def run(argv):
    if len(argv) > 1:
      raise app.UsageError(f"Unexpected arguments: {argv[1:]}")
    try:
      from mfsample.viewer.app import ViewerError, screenshot, serve
      from mfsample.viewer.browser import BrowserError
    except ImportError as e:  # viser, or matplotlib, missing
      sys.exit(f"error: the viewer needs the optional extra `viewer` ({e}): "
               'pip install -e ".[viewer]" in a clone')
    from mfsample.viewer.runs import RunError
    try:
      if shot.value:
        screenshot(workdir.value, shot.value)
        print(f"saved {shot.value}")
      else:
        serve(workdir.value, host=host.value, port=port.value, poll_seconds=poll.value)
    except (RunError, ViewerError, BrowserError) as e:
      sys.exit(f"error: {e}")

  app.run(run)
