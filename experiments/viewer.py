"""The capture planner in the browser: a job's workdir shown with viser (docs/viewer.md).

  python experiments/viewer.py --workdir=workdirs/camera_planning
  python experiments/viewer.py --workdir=workdirs/camera_planning \
      --screenshot=workdirs/camera_planning/viewer.png

Opens the workdir of the your-data job (experiments/next_views.py), camera planning or light
planning, finished or running, and prints the address to open. Binds to this machine only
(127.0.0.1) unless --host says otherwise; a running job's new steps appear as it writes them,
a workdir no job has written yet is waited for, and damaged files are named in the panel.
"""

import sys

from absl import app, flags

_WORKDIR = flags.DEFINE_string("workdir", None, "Workdir of a your-data, camera-planning or "
                               "light-planning job.")
_HOST = flags.DEFINE_string("host", "127.0.0.1", "Address to listen on: 127.0.0.1 (this "
                            "machine only); 0.0.0.0 for every interface (anyone who can reach "
                            "this machine can then see the scene: there is no login).")
_PORT = flags.DEFINE_integer("port", 8080, "Port to listen on (0: any free port).")
_POLL = flags.DEFINE_float("poll_seconds", 2.0, "How often the workdir is read again.")
_SCREENSHOT = flags.DEFINE_string("screenshot", None, "Save a PNG of the page as headless "
                                  "Chromium shows it at this path (its folder created), and "
                                  "exit.")
flags.mark_flags_as_required(["workdir"])


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f"Unexpected arguments: {argv[1:]}")
  try:
    from mfsample.viewer.app import ViewerError, screenshot, serve
    from mfsample.viewer.browser import BrowserError
  except ImportError as e:  # viser, or matplotlib, missing
    sys.exit(f"error: the viewer needs the optional extra `viewer` ({e}): "
             'pip install -e ".[viewer]"')
  from mfsample.viewer.runs import RunError
  try:
    if _SCREENSHOT.value:
      screenshot(_WORKDIR.value, _SCREENSHOT.value)
      print(f"saved {_SCREENSHOT.value}")
    else:
      serve(_WORKDIR.value, host=_HOST.value, port=_PORT.value, poll_seconds=_POLL.value)
  except (RunError, ViewerError, BrowserError) as e:
    sys.exit(f"error: {e}")


if __name__ == "__main__":
  app.run(main)
