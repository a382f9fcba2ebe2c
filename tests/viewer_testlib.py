"""Tiny workdirs of the jobs the viewer shows, written as the jobs write them, and a browser
tab stand-in: no training, no data, no Chromium (tests/viewer/test_viewer*.py)."""

import json
import os
import time

import numpy as np
from planning_testlib import random_model, tiny_config

from mfsample import config_record
from mfsample.planning import rounds
from mfsample.train import checkpoint as ckpt


def look_at(eye, target=(0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0)):
  """[4, 4] world-to-camera (OpenCV axes) of a camera at `eye` looking at `target`."""
  eye, target, up = (np.asarray(v, np.float64) for v in (eye, target, up))
  forward = (target - eye) / np.linalg.norm(target - eye)
  right = np.cross(forward, up)
  right /= np.linalg.norm(right)
  down = np.cross(forward, right)
  w2c = np.eye(4)
  w2c[:3, :3] = np.stack([right, down, forward])
  w2c[:3, 3] = -w2c[:3, :3] @ eye
  return w2c


def ring(n, radius=3.0, height=1.0):
  """[n, 4, 4] poses on a circle around the origin, looking at it."""
  angles = 2 * np.pi * np.arange(n) / n
  return np.stack([look_at((radius * np.cos(a), radius * np.sin(a), height)) for a in angles])


INTRINSICS = {"fx": 24.0, "fy": 24.0, "cx": 12.0, "cy": 12.0, "width": 24, "height": 24}


def _no_inputs(config, workdir):
  """The job's data moved away: the viewer shows what the workdir alone holds (and needs
  no dataset, so the tests take no rendering of ground truth)."""
  config.data.kind = "colmap"
  config.data.path = os.path.join(str(workdir), "moved-capture")


def next_views_workdir(workdir, steps=(10, 20), proposal=True, candidates=6, inputs=False):
  """A your-data workdir: checkpoints at `steps` and, with `proposal`, next_views.json
  ranking `candidates` candidates and results.json. With `inputs`, its config holds the
  tiny variant's data (random Gaussians rendered: seconds), else data that moved away."""
  from configs import next_views

  config = next_views.get_config("tiny")
  if not inputs:
    _no_inputs(config, workdir)
  config_record.write_config(config, str(workdir), {"job": "next_views"})
  model = random_model(num=20)
  for step in steps:
    ckpt.save_checkpoint(os.path.join(workdir, "checkpoints"), model,
                         {"step": step, "sampler": model.spec.to_dict()}, keep=len(steps))
  if proposal:
    u = np.linspace(0.1, 0.6, candidates)
    poses = ring(candidates)
    top = np.argsort(-u)[:2]
    record = {"u": u.tolist(), "names": [f"c{i}" for i in range(candidates)], "top_k": [
        {"rank": r + 1, "index": int(i), "name": f"scene-{i:012x}", "u": float(u[i]),
         "world_to_camera": poses[i].tolist(), "intrinsics": INTRINSICS}
        for r, i in enumerate(top)]}
    write_json(workdir / "next_views.json", record)
    write_json(workdir / "results.json", {"steps": int(steps[-1]) if steps else 0})
  return workdir


def write_json(path, value):
  path.write_text(json.dumps(value))


def planning_workdir(workdir, with_models=False):
  """A camera-planning workdir: the pool's 8 candidates and two rounds each of Ours (Sel.),
  which scores the candidates, and Ours (Opt. Rnd.), written after it, which scores none
  and chooses a pose outside the pool."""
  config = tiny_config()
  config.strategies = ("ours_sel", "ours_opt_rnd")
  _no_inputs(config, workdir)
  config_record.write_config(config, str(workdir), {"job": "camera_planning"})
  directory = workdir / rounds.DIRECTORY
  directory.mkdir()
  np.savez(directory / rounds.CANDIDATES, world_to_camera=ring(8),
           **{k: np.full(8, v) for k, v in INTRINSICS.items() if k[0] in "fc"},
           width=np.asarray(24), height=np.asarray(24))
  for name in ("ours_sel", "ours_opt_rnd"):
    for views in (1, 2):
      write_round(workdir, name, views, with_models)
  return workdir


def write_round(workdir, name, views, with_model=False):
  """Round `views` of `name` (seed 0) as `mfsample.planning.rounds` writes it: Ours (Sel.)
  scores the candidates (0 to 1) and chooses candidate `views`."""
  poses = ring(8)
  model = random_model(num=20)
  chosen = views if name == "ours_sel" else None
  label = {"ours_sel": "Ours (Sel.)", "ours_opt_rnd": "Ours (Opt. Rnd.)"}[name]
  meta = {"step": views, "strategy": name, "label": label, "seed": 0,
          "train": list(range(views)), "train_world_to_camera": poses[:views].tolist(),
          "chosen": {"index": chosen, "score": 0.5,
                     "world_to_camera": (poses[views] if chosen is not None else
                                         look_at((0.0, -2.0, 2.5))).tolist()},
          "scores": np.linspace(0.0, 1.0, 8).tolist() if name == "ours_sel" else None,
          "model": {"sampler": model.spec.to_dict()} if with_model else None}
  ckpt.save_checkpoint(str(workdir / rounds.DIRECTORY / f"{name}-seed0"),
                       model if with_model else {}, meta, keep=8)


def truncate(path, keep=0.5):
  """Cuts the file at `path` to `keep` of its bytes (a copy or a disk that ran out)."""
  data = open(path, "rb").read()
  with open(path, "wb") as f:
    f.write(data[:int(len(data) * keep)])


class Tab:
  """A browser tab as viser sees one (its websocket and first camera message), without a
  browser: `viewer.tabs[tab.id]` is then its panel and scene."""

  def __init__(self, viewer, timeout=30.0):
    import msgspec
    import viser
    from viser import _messages
    from websockets.sync.client import connect

    before = set(viewer.tabs)
    self.socket = connect(f"ws://127.0.0.1:{viewer.server.get_port()}", max_size=None,
                          subprotocols=[f"viser-v{viser.__version__}"])
    camera = _messages.ViewerCameraMessage((1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 3.0), 1.0, 0.01,
                                           100.0, 480, 640, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    self.socket.send(msgspec.msgpack.encode(camera.as_serializable_dict()))
    deadline = time.monotonic() + timeout
    while not (set(viewer.tabs) - before):
      if time.monotonic() > deadline:
        raise TimeoutError("the viewer built no tab for the new connection")
      time.sleep(0.02)
    (self.id,) = set(viewer.tabs) - before
    with viewer.lock:  # held while the tab is built and draws its first step
      self.tab = viewer.tabs[self.id]

  def close(self):
    self.socket.close()
