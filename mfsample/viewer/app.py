"""The capture planner in the browser: a viser server over one workdir.

`start(workdir, host, port)` opens the server and returns a `Viewer`; `serve` also follows the
run, polling its files every `poll_seconds`. The scene holds

  /splats                 the mean model of the shown step as Gaussian splats
  /train/<i>              the training cameras (dark grey)
  /candidates/<i>         the candidate cameras, coloured by their score (U) on the colour bar
  /next/<rank>            the proposed next views, largest first, in red with their rank
  /lights/sphere          light planning: U of a point light from each direction
  /lights/used/<i>        light planning: the lights trained on, and the chosen one in red

and the panel: the step shown (newest first while "follow the run" is on), the colour bar,
and for the camera chosen in the panel or clicked in the scene its mean render, its
per-pixel U map and the ground truth, when the workdir's inputs hold one.
"""

import dataclasses
import errno
import socket
import threading
import time

import numpy as np

from mfsample.viewer import models
from mfsample.viewer.runs import KINDS, open_run

TRAIN_COLOUR = (60, 60, 60)
UNSCORED_COLOUR = (170, 170, 170)
NEXT_COLOUR = (230, 30, 30)
COLORMAP = "viridis"
# Splat colourings: label -> field of `gaussian_uncertainty.GaussianUncertainty` (None: the
# model's own colour).
SPLAT_COLOURS = {"model colour": None, "share of U": "share",
                 "position std": "position_std", "colour std": "colour_std"}
PANEL_PIXELS = 144  # renders and maps are enlarged to about this width in the panel


class ViewerError(ValueError):
  """A viewer that cannot start (the message says why and what to do)."""


# ------------------------------------------------------------------ pure helpers


def colormap(values, lo=None, hi=None):
  """[N, 3] uint8 colours of `values` on the viewer's colour map, from `lo` to `hi`."""
  from matplotlib import colormaps

  values = np.asarray(values, np.float64)
  lo = float(np.min(values)) if lo is None else lo
  hi = float(np.max(values)) if hi is None else hi
  t = np.zeros_like(values) if hi <= lo else (values - lo) / (hi - lo)
  return (colormaps[COLORMAP](np.clip(t, 0.0, 1.0))[..., :3] * 255).astype(np.uint8)


def colour_bar(width=256, height=16):
  """[height, width, 3] uint8: the colour map from low (left) to high (right)."""
  return np.repeat(colormap(np.linspace(0.0, 1.0, width))[None], height, axis=0)


def enlarge(image, width=PANEL_PIXELS):
  """`image` [H, W, (3)] enlarged by an integer factor (nearest pixel) to about `width`."""
  image = np.asarray(image)
  factor = max(1, int(width) // max(image.shape[1], 1))
  return np.repeat(np.repeat(image, factor, axis=0), factor, axis=1)


def to_uint8(rgb):
  return (np.clip(np.asarray(rgb, np.float64), 0.0, 1.0) * 255 + 0.5).astype(np.uint8)


def camera_pose(camera):
  """(wxyz [4], position [3]) of an unbatched `Camera` (OpenCV axes, as viser's frustums)."""
  import viser.transforms as vtf

  c2w = np.linalg.inv(np.asarray(camera.world_to_camera, np.float64))
  return vtf.SO3.from_matrix(c2w[:3, :3]).wxyz, c2w[:3, 3]


def look_at_point(cameras):
  """[3] the point nearest to every camera's optical axis (least squares), or the mean of
  the centres when the axes are parallel."""
  w2c = np.asarray(cameras.world_to_camera, np.float64).reshape(-1, 4, 4)
  rot, t = w2c[:, :3, :3], w2c[:, :3, 3]
  centres = -np.einsum("nji,nj->ni", rot, t)
  axes = rot[:, 2, :]  # the camera's +z (forward) in world coordinates
  proj = np.eye(3)[None] - axes[:, :, None] * axes[:, None, :]
  a, b = proj.sum(0), np.einsum("nij,nj->i", proj, centres)
  if np.linalg.cond(a) > 1e8:
    return centres.mean(0)
  return np.linalg.solve(a, b)


@dataclasses.dataclass
class Frame:
  """Where the scene is: its centre, the cameras' distance from it and the up direction."""

  centre: np.ndarray
  radius: float
  up: np.ndarray
  view_distance: float = 0.0  # of a new client's camera from the centre (0: 2.2 radius)


def scene_frame(step, model=None):
  """The `Frame` of a step's cameras (or of its model's Gaussians when it has none)."""
  from mfsample.viewer.runs import Camera
  from mfsample.your_data.candidates import capture_up

  groups = [g[0] for g in (step.train, step.candidates) if g is not None]
  groups += [p.camera for p in step.proposals]
  if groups:
    w2c = np.concatenate([np.asarray(g.world_to_camera, np.float64).reshape(-1, 4, 4)
                          for g in groups])
    cams = Camera(w2c, np.ones(len(w2c)), np.ones(len(w2c)), np.ones(len(w2c)),
                  np.ones(len(w2c)), 1, 1)
    centre = look_at_point(cams)
    centres = np.linalg.inv(w2c)[:, :3, 3]
    radius = float(np.median(np.linalg.norm(centres - centre, axis=-1)))
    return Frame(centre, max(radius, 1e-3), capture_up(cams))
  if model is not None:
    means = np.asarray(model.params.mean["means"])[models.live(model)]
    centre = means.mean(0)
    return Frame(centre, float(np.linalg.norm(means - centre, axis=-1).max()) * 2.5 + 1e-3,
                 np.array([0.0, 0.0, 1.0]))
  return Frame(np.zeros(3), 1.0, np.array([0.0, 0.0, 1.0]))


def check_port(host, port):
  """Raises ViewerError when `port` on `host` is taken (viser would move to another port
  without saying so) or `host` is not an address of this machine."""
  if int(port) == 0:
    return
  try:
    infos = socket.getaddrinfo(host, int(port), type=socket.SOCK_STREAM)
  except socket.gaierror as e:
    raise ViewerError(f"--host={host}: not an address ({e})") from e
  family, _, _, _, address = infos[0]
  with socket.socket(family, socket.SOCK_STREAM) as s:
    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the server will
    try:
      s.bind(address)
    except OSError as e:
      if e.errno == errno.EADDRINUSE:
        raise ViewerError(f"port {port} on {host} is in use: pass another --port, or "
                          "--port=0 for any free one") from e
      raise ViewerError(f"cannot listen on {host}:{port} ({e.strerror})") from e


# ------------------------------------------------------------------ the viewer


class Viewer:
  """The scene and panel of one run on a viser server (see the module docstring)."""

  def __init__(self, server, run):
    self.server = server
    self.run = run
    self.steps = []
    self.step = None
    self.handles = {}  # scene node name -> handle of what the current step drew
    self.splat_key = None
    self.frame = None
    self.cameras = {}  # camera choice label -> (group, index)
    # The render budget that sufficed so far (it only grows: later views of the same size
    # reuse the compiled renders).
    self.render_settings = models.START
    self.gaussian_cache = {}
    self.lock = threading.RLock()
    self._build_panel()
    server.on_client_connect(self._on_connect)

  # ---------------------------------------------------------------- panel

  def _build_panel(self):
    gui = self.server.gui
    gui.add_markdown(f"**mfsample** · {KINDS[self.run.kind]}  \n`{self.run.workdir}`")
    self.status = gui.add_markdown("reading the workdir…")
    self.step_dropdown = gui.add_dropdown("step", ("(none yet)",))
    self.follow = gui.add_checkbox("follow the run", True,
                                   hint="show the newest step as the job writes it")
    self.splat_colour = gui.add_dropdown(
        "splat colour", tuple(SPLAT_COLOURS),
        hint="colour the Gaussians by their own colour or by their uncertainty "
             "(mfsample.gaussian_uncertainty)")
    self.splat_label = gui.add_markdown("")
    self.note = gui.add_markdown("")
    self.bar_label = gui.add_markdown("")
    self.bar = gui.add_image(colour_bar(), label=None)
    self.camera_dropdown = gui.add_dropdown("camera", ("(none)",))
    self.camera_info = gui.add_markdown("")
    blank = np.zeros((8, 8, 3), np.uint8)
    self.render_image = gui.add_image(blank, label="mean render")
    self.u_image = gui.add_image(blank, label="U map")
    self.truth_image = gui.add_image(blank, label="ground truth")

    @self.step_dropdown.on_update
    def _(event):
      if event.client is not None:  # a person chose a step: stop following
        self.follow.value = False
      self._show_step_named(self.step_dropdown.value)

    @self.camera_dropdown.on_update
    def _(_):
      self.show_camera(self.camera_dropdown.value)

    @self.splat_colour.on_update
    def _(_):
      with self.lock:
        if self.step is not None:
          self._draw_splats(self.step, self.run.model(self.step))

  def _on_connect(self, client):
    """Points a new client's camera at the scene, from above the first proposal (or from an
    oblique side), so the proposal and its label face the viewer."""
    frame = self.frame
    if frame is None:
      return
    direction = np.array([1.0, -1.2, 0.0])
    if self.step is not None and self.step.proposals:
      direction = camera_pose(self.step.proposals[0].camera)[1] - frame.centre
    direction = direction - frame.up * (direction @ frame.up)
    direction = direction / max(np.linalg.norm(direction), 1e-12) + 0.9 * frame.up
    direction /= np.linalg.norm(direction)
    client.camera.up_direction = tuple(frame.up)
    distance = frame.view_distance or 2.2 * frame.radius
    client.camera.position = tuple(frame.centre + direction * distance)
    client.camera.look_at = tuple(frame.centre)

  # ---------------------------------------------------------------- following the run

  def refresh(self):
    """Re-reads the workdir; draws the newest step (following) or redraws the shown one
    when its files changed."""
    with self.lock:
      self.run.load_inputs()
      steps = self.run.steps()
      titles = [s.title for s in steps]
      if titles != [s.title for s in self.steps]:
        self.step_dropdown.options = tuple(titles) or ("(none yet)",)
      self.steps = steps
      if not steps:
        self.status.content = "the job has written no step yet: waiting for it"
        return
      current = next((s for s in steps if self.step and s.key == self.step.key), None)
      target = steps[-1] if (self.follow.value or current is None) else current
      if self.step is None or target.key != self.step.key or (
          target.signature != self.step.signature):
        self.show_step(target)
      self.status.content = f"{len(steps)} step(s) · polled {time.strftime('%H:%M:%S')}"

  def _show_step_named(self, title):
    with self.lock:
      step = next((s for s in self.steps if s.title == title), None)
      if step is not None and (self.step is None or step.key != self.step.key):
        self.show_step(step)

  def show_step(self, step):
    """Draws `step`: splats, cameras, colour bar, and the light sphere of light planning."""
    with self.lock:
      self.step = step
      if self.step_dropdown.value != step.title:
        self.step_dropdown.value = step.title
      # Children (labels) before their parents: removing a parent removes them too.
      for name in sorted(self.handles, key=lambda n: -n.count("/")):
        self.handles[name].remove()
      self.handles, self.cameras = {}, {}
      model = self.run.model(step)
      self.frame = scene_frame(step, model)
      self.server.scene.set_up_direction(tuple(float(v) for v in self.frame.up))
      self._draw_splats(step, model)
      self._draw_cameras(step)
      if step.q is not None or step.lights:
        self._draw_lights(step)
      self.note.content = f"*{step.note}*" if step.note else ""
      self._fill_camera_choices(step)

  def _add(self, name, handle):
    self.handles[name] = handle
    return handle

  def _draw_splats(self, step, model):
    colouring = self.splat_colour.value
    key = (step.model_path, step.signature, self._light_key(step), colouring)
    if key == self.splat_key and "/splats" in self.handles:
      return
    self.splat_label.content = ""
    if model is None or not np.any(models.live(model)):
      return
    relightable = models.is_relightable(model)
    self.splat_colour.disabled = relightable  # per-Gaussian U is defined for SH colour
    eye = self.frame.centre + self.frame.up * self.frame.radius
    light = self.run.light_of(step) if hasattr(self.run, "light_of") else None
    centres, cov, rgb, opacity = models.splats(model, eye, light)
    if SPLAT_COLOURS[colouring] and not relightable:
      values = self._per_gaussian(step, model)
      if values is not None:
        values = np.asarray(getattr(values, SPLAT_COLOURS[colouring]))[models.live(model)]
        hi = float(np.percentile(values, 99)) if values.size else 0.0
        rgb = colormap(values, 0.0, hi if hi > 0 else 1.0).astype(np.float32) / 255.0
        self.splat_label.content = (f"splats coloured by {colouring}: 0 (left) to {hi:.3g} "
                                    "(right; the top 1% at the right end)")
    if "/splats" in self.handles:
      self.handles.pop("/splats").remove()
    self._add("/splats", self.server.scene.add_gaussian_splats(
        "/splats", centers=centres, covariances=cov, rgbs=rgb, opacities=opacity))
    self.splat_key = key

  def _per_gaussian(self, step, model):
    """`GaussianUncertainty` of the step's model over the views it scores (the candidates,
    else the training views), at the job's scoring size; computed once per step."""
    from mfsample.gaussian_uncertainty import gaussian_uncertainty
    from mfsample.planning.poses import downscale_camera

    key = (step.model_path, step.signature)
    if key not in self.gaussian_cache:
      group = step.candidates if step.candidates is not None else step.train
      if group is None:
        return None
      self.splat_label.content = (f"computing each Gaussian's uncertainty over "
                                  f"{len(group[1])} views…")
      num, seed = self.run.u_samples()
      cameras = downscale_camera(group[0], self.run.score_downscale())
      self.gaussian_cache = {key: gaussian_uncertainty(
          model, cameras, models.samples(model, num, seed), settings=self.render_settings,
          background=np.asarray(self.run.background(), np.float32))}
    return self.gaussian_cache[key]

  def _light_key(self, step):
    if not hasattr(self.run, "light_of"):
      return None
    light = self.run.light_of(step)
    return None if light is None else tuple(np.round(light, 6))

  def _frustum(self, name, camera, colour, scale):
    wxyz, position = camera_pose(camera)
    fov = 2.0 * np.arctan(0.5 * camera.height / float(np.asarray(camera.fy)))
    handle = self.server.scene.add_camera_frustum(
        name, fov=float(fov), aspect=camera.width / camera.height, scale=scale,
        color=tuple(int(c) for c in colour), wxyz=wxyz, position=position)
    return self._add(name, handle)

  def _draw_cameras(self, step):
    count = sum(len(g[1]) for g in (step.train, step.candidates) if g is not None)
    scale = (0.12 if count <= 30 else 0.07) * self.frame.radius  # many cameras: smaller
    if step.train is not None:
      cams, names = step.train
      for i in range(len(names)):
        self._clickable(self._frustum(f"/train/{i}", cams[i], TRAIN_COLOUR, scale),
                        self._label("train", i, names[i]))
    scores = step.scores
    self.bar.visible = self.bar_label.visible = False
    if step.candidates is not None:
      cams, names = step.candidates
      if scores is not None:
        finite = np.isfinite(scores)
        lo, hi = (float(np.min(scores[finite])), float(np.max(scores[finite]))) if (
            finite.any()) else (0.0, 1.0)
        colours = colormap(np.where(finite, scores, lo), lo, hi)
        self.bar_label.content = (f"candidates coloured by {step.score_name}: "
                                  f"{lo:.4g} (left) to {hi:.4g} (right)")
        self.bar.visible = self.bar_label.visible = True
      else:
        colours = np.tile(np.array(UNSCORED_COLOUR, np.uint8), (len(names), 1))
      for i in range(len(names)):
        self._clickable(self._frustum(f"/candidates/{i}", cams[i], colours[i], scale),
                        self._label("candidates", i, names[i]))
    for p in step.proposals:
      name = f"/next/{p.rank}"
      group, index = ("candidates", p.index) if (
          p.index is not None and step.candidates is not None) else ("next", p.rank - 1)
      self._clickable(self._frustum(name, p.camera, NEXT_COLOUR, scale * 1.5),
                      self._label(group, index, p.name, p))
      _, position = camera_pose(p.camera)
      score = "" if p.score is None else f" ({step.score_name} {p.score:.4g})"
      self._add(f"{name}/label", self.server.scene.add_label(
          f"{name}/label", f"next #{p.rank}{score}", position=(0.0, 0.0, 0.0)))

  def _draw_lights(self, step):
    from mfsample.lighting import lights as lights_lib
    from mfsample.lighting.figures import u_over_directions

    radius = 1.4 * self.frame.radius
    self.frame.view_distance = 2.4 * radius
    if step.q is not None:
      values, dirs = u_over_directions(step.q, lights_lib.UNIFORM_NORM, 32, 64)
      lo, hi = float(values.min()), float(values.max())
      self._add("/lights/sphere", self.server.scene.add_point_cloud(
          "/lights/sphere", points=(self.frame.centre + radius * dirs.reshape(-1, 3)
                                    ).astype(np.float32),
          colors=colormap(values.ravel(), lo, hi), point_size=0.035 * self.frame.radius,
          point_shape="circle"))
      self.bar_label.content = (f"sphere of light directions coloured by U of a point light "
                                f"from there: {lo:.4g} (left) to {hi:.4g} (right)")
      self.bar.visible = self.bar_label.visible = True
    marked = list(step.lights) + ([step.next_light] if step.next_light else [])
    dirs, _ = lights_lib.direction_grid(32, 64)
    flat = dirs.reshape(-1, 3)
    for i, (label, xi) in enumerate(marked):
      brightest = flat[int(np.argmax(lights_lib.environment(xi, flat)))]
      chosen = step.next_light is not None and i == len(marked) - 1
      name = f"/lights/used/{i}"
      position = self.frame.centre + radius * 1.08 * brightest
      self._add(name, self.server.scene.add_point_cloud(
          name, points=np.zeros((1, 3), np.float32),
          colors=NEXT_COLOUR if chosen else TRAIN_COLOUR, point_size=0.2 * self.frame.radius,
          point_shape="circle", position=tuple(float(v) for v in position)))
      text = f"{'chosen: ' if chosen else ''}{label}"
      self._add(f"{name}/label", self.server.scene.add_label(f"{name}/label", text,
                                                             position=(0.0, 0.0, 0.0)))

  # ---------------------------------------------------------------- one camera

  def _label(self, group, index, name, proposal=None):
    prefix = {"train": "train", "candidates": "candidate", "next": "next"}[group]
    if proposal is not None:
      prefix = f"next #{proposal.rank}"
    return f"{prefix}: {name}", (group, index)

  def _clickable(self, handle, choice):
    label, _ = choice
    self.cameras[label] = choice[1]

    @handle.on_click
    def _(_):
      self.camera_dropdown.value = label

  def _fill_camera_choices(self, step):
    labels = list(self.cameras)
    # Keep only the labels this step drew; the proposals first.
    drawn = [label for label in labels if label.startswith("next")] + [
        label for label in labels if not label.startswith("next")]
    self.cameras = {label: self.cameras[label] for label in drawn}
    self.camera_dropdown.options = tuple(drawn) or ("(none)",)
    if not drawn:
      return
    if self.camera_dropdown.value == drawn[0]:  # unchanged: viser calls no callback
      self.show_camera(drawn[0])
    else:
      self.camera_dropdown.value = drawn[0]

  def camera_of(self, step, group, index):
    if group == "next":
      return step.proposals[index].camera
    cams = (step.train if group == "train" else step.candidates)[0]
    return cams[int(index)]

  def show_camera(self, label):
    """Fills the panel with the mean render, U map and ground truth of camera `label`."""
    with self.lock:
      step, choice = self.step, self.cameras.get(label)
      if step is None or choice is None:
        return
      group, index = choice
      camera = self.camera_of(step, group, index)
      truth = self.run.ground_truth(step, group, index) if group != "next" else None
      text = [f"**{label}**"]
      if group == "candidates" and step.scores is not None:
        text.append(f"{step.score_name} as the job scored it: {step.scores[int(index)]:.4g}")
      self.truth_image.visible = truth is not None
      if truth is not None:
        self.truth_image.image = enlarge(to_uint8(truth))
      model = self.run.model(step)
      if model is None:
        text.append("no model to render for this step")
        self.render_image.visible = self.u_image.visible = False
      else:
        self.camera_info.content = "  \n".join(text + ["rendering…"])
        rgb, pmap, u = self._render(step, model, camera)
        hi = float(pmap.max()) if pmap.size else 0.0
        self.render_image.image = enlarge(to_uint8(rgb))
        self.u_image.image = enlarge(colormap(pmap, 0.0, hi if hi > 0 else 1.0))
        self.render_image.visible = self.u_image.visible = True
        text.append(f"U of this view at {camera.width} x {camera.height}: {u:.4g} "
                    f"(map: 0 to {hi:.3g})")
      self.camera_info.content = "  \n".join(text)

  def _render(self, step, model, camera):
    num, seed = self.run.u_samples()
    z = models.samples(model, num, seed)
    if models.is_relightable(model):
      rgb, pmap, u, self.render_settings = models.render_relit(
          model, camera, z, self.run.light_of(step), self.render_settings)
    else:
      rgb, pmap, u, self.render_settings = models.render_colour(
          model, camera, z, self.run.background(), self.render_settings)
    return rgb, pmap, u


# ------------------------------------------------------------------ serving


def start(workdir, host="127.0.0.1", port=8080):
  """Opens the run in `workdir`, starts the server and draws the newest step.

  Returns:
    the `Viewer`; its `server.get_port()` is the port bound (useful with port 0).

  Raises:
    mfsample.viewer.runs.RunError: the workdir holds no run of a known kind.
    ViewerError: the port is taken or the host is not an address of this machine.
  """
  import viser

  run = open_run(workdir)
  check_port(host, port)
  server = viser.ViserServer(host=host, port=int(port), verbose=False)
  if int(port) != 0 and server.get_port() != int(port):  # taken between the check and now
    server.stop()
    raise ViewerError(f"port {port} on {host} is in use: pass another --port, or --port=0")
  viewer = Viewer(server, run)
  viewer.refresh()
  return viewer


def serve(workdir, host="127.0.0.1", port=8080, poll_seconds=2.0, on_start=print):
  """`start`, then follows the run until interrupted (Ctrl-C)."""
  viewer = start(workdir, host, port)
  shown = "localhost" if host in ("127.0.0.1", "::1", "localhost") else host
  try:
    on_start(f"mfsample viewer: {KINDS[viewer.run.kind]} in {workdir}\n"
             f"  open http://{shown}:{viewer.server.get_port()} (bound to {host}; Ctrl-C "
             "stops)")
    while True:
      time.sleep(float(poll_seconds))
      viewer.refresh()
  except KeyboardInterrupt:
    pass
  finally:
    viewer.server.stop()


def screenshot(workdir, path, *, max_width=1100, size=(1280, 860), timeout=120.0, settle=10.0):
  """Saves a PNG of the viewer's page on `workdir` as headless Chromium shows it (the newest
  step, its first proposal in the panel), and returns the `Viewer` (stopped). viser fades new
  objects in; with WebGL in software that takes seconds, hence `settle`.

  Raises:
    mfsample.viewer.browser.BrowserError: no Chromium, or the page did not load in time.
  """
  from mfsample.viewer.browser import Browser

  viewer = start(workdir, port=0)
  try:
    with Browser(size=size, timeout=timeout) as browser:
      browser.open(f"http://127.0.0.1:{viewer.server.get_port()}/")
      browser.wait_for_text(viewer.step.title if viewer.step else "mfsample")
      browser.screenshot(path, max_width=max_width, settle=settle)
  finally:
    viewer.server.stop()
  return viewer
