"""The capture planner in the browser: a viser server over one workdir.

`start(workdir, host, port)` opens the server and returns a `Viewer`; `serve` also follows the
run, polling its files every `poll_seconds`, and waits for a run that a job has not begun
writing yet. Every browser tab gets its own panel and scene (`Tab`): the step, camera,
colouring and toggles chosen in one tab do not move another. A tab's scene holds

  /splats                 the mean model of the shown step as Gaussian splats
  /train/<i>              the training cameras (dark grey; the toggle "training cameras")
  /candidates/<i>         the candidate cameras, coloured by their score (U) on magma
                          (the toggle "candidates")
  /next/<rank>            the proposed next views, "next view 1" first, in red
  /lights/sphere          light planning: U of a point light from each direction
  /lights/used/<i>        light planning: the lights trained on, and the chosen one in red

and its panel: the state of the run (waiting, polled, damaged files), the step shown (by
default the newest that colours its candidates or lights), the chosen camera's ground truth,
mean render and U map side by side, with U at the size the job scores at, and one colour bar
per coloured quantity (candidates or lights; splats).
"""

import collections
import dataclasses
import errno
import os
import socket
import threading
import time

import numpy as np

from mfsample.viewer import models
from mfsample.viewer.runs import KINDS, NoRunYet, RunError, default_step, open_run

TRAIN_COLOUR = (60, 60, 60)
UNSCORED_COLOUR = (170, 170, 170)
NEXT_COLOUR = (230, 30, 30)
COLORMAP = "magma"  # as the job's PNGs and uncertainty .ply files
# Splat colourings: label -> field of `gaussian_uncertainty.GaussianUncertainty` (None: the
# model's own colour).
SPLAT_COLOURS = {"model colour": None, "share of U": "share",
                 "position std": "position_std", "colour std": "colour_std"}
PANEL_PIXELS = 144  # an image alone is enlarged to about this width in the panel
STRIP_HEIGHT = 120  # rows of the ground truth, render and U map shown side by side
RENDERS_KEPT = 32  # renders of cameras kept for the tabs (a tab reopening a camera)


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


def views_strip(images, height=STRIP_HEIGHT, gap=6):
  """[height, W, 3] uint8: `images` ([H_i, W_i, 3] uint8 each) side by side on white, each
  scaled (nearest pixel) to `height` rows, so that maps of other sizes line up."""
  from PIL import Image

  scaled = [np.asarray(Image.fromarray(np.asarray(im, np.uint8)).resize(
      (max(1, round(im.shape[1] * height / im.shape[0])), height), Image.NEAREST))
      for im in images]
  width = sum(im.shape[1] for im in scaled) + gap * (len(scaled) - 1)
  out = np.full((height, max(width, 1), 3), 255, np.uint8)
  x = 0
  for im in scaled:
    out[:, x:x + im.shape[1]] = im
    x += im.shape[1] + gap
  return out


# ------------------------------------------------------------------ the viewer


class Viewer:
  """One run on a viser server: what every tab shares (the run, its steps, the models and
  renders read so far) and a `Tab` per connected browser tab.

  Attributes:
    run: the `Run`, or None while no job has written the workdir (`waiting` says why).
    steps: the run's steps at the last `refresh`.
    error: why the last `refresh` could not read the run ("" when it could).
    tabs: client id -> `Tab`.
  """

  def __init__(self, server, workdir, run=None):
    self.server = server
    self.workdir = os.fspath(workdir)
    self.run = run
    self.steps = []
    self.waiting = ""
    self.error = ""
    self.polled = ""
    self.tabs = {}
    # The render budget that sufficed so far (it only grows: later views of the same size
    # reuse the compiled renders).
    self.render_settings = models.START
    self.gaussian_cache = {}
    self.render_cache = collections.OrderedDict()
    self.lock = threading.RLock()
    # A wide panel: step titles and the three images side by side stay readable.
    server.gui.configure_theme(control_width="large")
    server.on_client_connect(self._connect)
    server.on_client_disconnect(self._disconnect)

  def _connect(self, client):
    with self.lock:
      tab = Tab(self, client)
      self.tabs[client.client_id] = tab
      tab.update()

  def _disconnect(self, client):
    with self.lock:
      self.tabs.pop(client.client_id, None)

  def refresh(self):
    """Re-reads the workdir and updates every tab. Nothing the workdir holds ends the
    viewer: a run not begun yet is waited for, and damage is shown in the panel (the last
    state read stays on screen)."""
    with self.lock:
      try:
        if self.run is None:
          self.run = open_run(self.workdir)
          self.waiting = ""
        self.run.load_inputs()
        self.steps = self.run.steps()
        self.error = ""
      except NoRunYet as e:
        self.waiting = f"waiting for a job to write {self.workdir}: {e}"
      except RunError as e:  # a config.json written since, that cannot be shown
        self.waiting = f"{e}; waiting for a run it can show"
      except Exception as e:  # noqa: BLE001 - whatever the files hold, the viewer stays up
        self.error = (f"reading the run in {self.workdir} failed ({type(e).__name__}: {e}); "
                      "the last state read is shown, and read again at the next poll")
      self.polled = time.strftime("%H:%M:%S")
      for tab in list(self.tabs.values()):
        tab.update()

  def status_lines(self):
    """The state of the run for the panel: waiting, errors, damaged files, the newest step."""
    lines = []
    if self.waiting:
      lines.append(f"**{self.waiting}**")
    if self.error:
      lines.append(f"**{self.error}**")
    if self.run is not None:
      if self.steps:
        newest = self.steps[-1].title
        lines.append(f"{len(self.steps)} step(s), the newest: {newest} · polled {self.polled}")
      elif not self.waiting:
        lines.append(f"the job has written no step yet: waiting for it · polled {self.polled}")
      problems = self.run.problems
      if problems:
        lines.append(f"**{len(problems)} damaged file(s)**, listed at the end of the panel; "
                     "the rest of the run is shown")
    return lines

  def problem_lines(self):
    """The damaged files, one line each naming the file and what is wrong with it."""
    problems = self.run.problems if self.run is not None else ()
    return (["**damaged files**"] + [f"- {p}" for p in problems]) if problems else []

  # ---------------------------------------------------------------- shared computations

  def per_gaussian(self, step, model):
    """`GaussianUncertainty` of the step's model over the views it scores (the candidates,
    else the training views), at the job's scoring size; computed once per step."""
    from mfsample.gaussian_uncertainty import gaussian_uncertainty
    from mfsample.planning.poses import downscale_camera

    key = (step.model_path, step.signature)
    if key not in self.gaussian_cache:
      group = step.candidates if step.candidates is not None else step.train
      if group is None:
        return None
      num, seed = self.run.u_samples()
      cameras = downscale_camera(group[0], self.run.score_downscale())
      self.gaussian_cache = {key: gaussian_uncertainty(
          model, cameras, models.samples(model, num, seed), settings=self.render_settings,
          background=np.asarray(self.run.background(), np.float32))}
    return self.gaussian_cache[key]

  def renders(self, step, model, camera, key):
    """(mean render [H, W, 3], U map [h, w], U) of `camera` for `step` (cached under `key`):
    the render at the camera's size, U at the size the job scores at (the same definition
    as the job's scores)."""
    from mfsample.planning.poses import downscale_camera

    key = (step.key, step.signature, key)
    if key in self.render_cache:
      self.render_cache.move_to_end(key)
      return self.render_cache[key]
    num, seed = self.run.u_samples()
    z = models.samples(model, num, seed)
    light = self.run.light_of(step)
    rgb, self.render_settings = models.render_image(
        model, camera, self.run.background(), light, self.render_settings)
    small = downscale_camera(camera, self.run.score_downscale())
    pmap, u, self.render_settings = models.render_u(
        model, small, z, self.run.background(), light, self.render_settings)
    self.render_cache[key] = (rgb, pmap, u)
    while len(self.render_cache) > RENDERS_KEPT:
      self.render_cache.popitem(last=False)
    return rgb, pmap, u


class Tab:
  """The panel and scene of one browser tab: its own step, camera, colouring and toggles."""

  def __init__(self, viewer, client):
    self.viewer = viewer
    self.client = client
    self.scene = client.scene
    self.step = None
    self.titles = None
    self.handles = {}  # scene node name -> handle of what the current step drew
    self.splat_key = None
    self.frame = None
    self.placed = False  # whether the tab's camera was pointed at the scene
    self.cameras = {}  # camera choice label -> (group, index)
    # Set while the viewer itself changes a dropdown's options (viser may move its value
    # then): its callbacks wait for the value the viewer sets next.
    self.quiet = False
    self._build_panel(client.gui)

  # ---------------------------------------------------------------- panel

  def _build_panel(self, gui):
    self.header = gui.add_markdown(self._header())
    self.status = gui.add_markdown("reading the workdir…")
    self.step_dropdown = gui.add_dropdown("step", ("(none yet)",))
    self.step_title = gui.add_markdown("")  # the whole title: a dropdown cuts long ones
    self.follow = gui.add_checkbox(
        "follow the run", True,
        hint="show the newest step that colours its candidates or lights, as the job writes it")
    self.note = gui.add_markdown("")
    self.camera_dropdown = gui.add_dropdown("camera", ("(none)",))
    self.camera_info = gui.add_markdown("")
    self.views_image = gui.add_image(np.full((8, 8, 3), 255, np.uint8), label=None)
    self.views_image.visible = False
    self.bar_label = gui.add_markdown("")
    self.bar = gui.add_image(colour_bar(), label=None)
    with gui.add_folder("display"):
      self.show_train = gui.add_checkbox("training cameras", True,
                                         hint="show the training cameras' frustums")
      self.show_candidates = gui.add_checkbox("candidates", True,
                                              hint="show the candidates' frustums")
      self.splat_colour = gui.add_dropdown(
          "splat colour", tuple(SPLAT_COLOURS),
          hint="colour the Gaussians by their own colour or by their uncertainty "
               "(mfsample.gaussian_uncertainty)")
      self.splat_label = gui.add_markdown("")
      self.splat_bar = gui.add_image(colour_bar(), label=None)
    self.bar.visible = self.splat_bar.visible = False
    # Last: a long list must not push the views out of sight.
    self.problems = gui.add_markdown("")

    @self.step_dropdown.on_update
    def _(event):
      if self.quiet:
        return
      if event.client is not None:  # a person chose a step: stop following
        self.follow.value = False
      self.guarded(lambda: self.show_step_named(self.step_dropdown.value))

    @self.follow.on_update
    def _(_):
      if self.follow.value:
        self.update()

    @self.camera_dropdown.on_update
    def _(_):
      if not self.quiet:
        self.show_camera(self.camera_dropdown.value)

    @self.splat_colour.on_update
    def _(_):
      if self.step is not None:
        self.guarded(lambda: self._draw_splats(self.step, self.viewer.run.model(self.step)))

    @self.show_train.on_update
    def _(_):
      self._apply_toggles()

    @self.show_candidates.on_update
    def _(_):
      self._apply_toggles()

  def _header(self):
    run = self.viewer.run
    kind = KINDS[run.kind] if run is not None else "no run yet"
    return f"**mfsample** · {kind}  \n`{self.viewer.workdir}`"

  def _apply_toggles(self):
    with self.viewer.lock:
      for name, handle in self.handles.items():
        if name.startswith("/train/"):
          handle.visible = self.show_train.value
        elif name.startswith("/candidates/"):
          handle.visible = self.show_candidates.value

  # ---------------------------------------------------------------- following the run

  def update(self):
    """Shows the viewer's latest read of the run: the default step while following, else
    the chosen one redrawn when its files changed. Errors are shown, never raised."""
    self.guarded(self._update)

  def guarded(self, draw):
    """Runs `draw()` under the viewer's lock, then shows the run's state in the panel; an
    error of drawing is shown there too (one bad step must not take the tab down)."""
    with self.viewer.lock:
      try:
        draw()
        error = ""
      except Exception as e:  # noqa: BLE001 - shown in the panel, the tab stays up
        error = f"**drawing the step failed** ({type(e).__name__}: {e})"
      self.status.content = "  \n".join(self.viewer.status_lines() + ([error] if error else []))
      self.problems.content = "\n".join(self.viewer.problem_lines())

  def _update(self):
    header = self._header()
    if self.header.content != header:
      self.header.content = header
    steps = self.viewer.steps
    titles = tuple(s.title for s in steps)
    if titles != self.titles:
      self.titles = titles
      self.quiet = True
      try:
        self.step_dropdown.options = titles or ("(none yet)",)
      finally:
        self.quiet = False
    if not steps:
      return
    current = next((s for s in steps if self.step and s.key == self.step.key), None)
    target = default_step(steps) if (self.follow.value or current is None) else current
    if self.step is None or target.key != self.step.key or (
        target.signature != self.step.signature):
      self.show_step(target)

  def show_step_named(self, title):
    with self.viewer.lock:
      step = next((s for s in self.viewer.steps if s.title == title), None)
      if step is not None and (self.step is None or step.key != self.step.key):
        self.show_step(step)

  def show_step(self, step):
    """Draws `step`: splats, cameras, colour bars, and the light sphere of light planning."""
    with self.viewer.lock:
      self.step = step
      if self.step_dropdown.value != step.title:
        self.step_dropdown.value = step.title
      self.step_title.content = f"**{step.title}**"
      # Children (labels) before their parents: removing a parent removes them too.
      for name in sorted(self.handles, key=lambda n: -n.count("/")):
        self.handles[name].remove()
      self.handles, self.cameras = {}, {}
      model = self.viewer.run.model(step)
      self.frame = scene_frame(step, model)
      self.scene.set_up_direction(tuple(float(v) for v in self.frame.up))
      self.bar.visible = False
      self.bar_label.content = ""
      self._draw_splats(step, model)
      self._draw_cameras(step)
      if step.q is not None or step.lights:
        self._draw_lights(step)
      self.note.content = f"*{step.note}*" if step.note else ""
      self._fill_camera_choices(step)
      if not self.placed:
        self._place_camera()

  def _place_camera(self):
    """Points the tab's camera at the scene, from above the first proposal (or from an
    oblique side), so the proposal and its label face the viewer."""
    frame = self.frame
    direction = np.array([1.0, -1.2, 0.0])
    if self.step is not None and self.step.proposals:
      direction = camera_pose(self.step.proposals[0].camera)[1] - frame.centre
    direction = direction - frame.up * (direction @ frame.up)
    direction = direction / max(np.linalg.norm(direction), 1e-12) + 0.9 * frame.up
    direction /= np.linalg.norm(direction)
    distance = frame.view_distance or 2.2 * frame.radius
    camera = self.client.camera
    camera.up_direction = tuple(frame.up)
    camera.position = tuple(frame.centre + direction * distance)
    camera.look_at = tuple(frame.centre)
    self.placed = True

  def _add(self, name, handle):
    self.handles[name] = handle
    return handle

  def _draw_splats(self, step, model):
    colouring = self.splat_colour.value
    light = self.viewer.run.light_of(step)
    key = (step.model_path, step.signature,
           None if light is None else tuple(np.round(light, 6)), colouring)
    if key == self.splat_key and "/splats" in self.handles:
      return
    self.splat_label.content = ""
    self.splat_bar.visible = False
    if "/splats" in self.handles:
      self.handles.pop("/splats").remove()
    if model is None or not np.any(models.live(model)):
      return
    relightable = models.is_relightable(model)
    self.splat_colour.disabled = relightable  # per-Gaussian U is defined for SH colour
    eye = self.frame.centre + self.frame.up * self.frame.radius
    centres, cov, rgb, opacity = models.splats(model, eye, light)
    if SPLAT_COLOURS[colouring] and not relightable:
      self.splat_label.content = "computing each Gaussian's uncertainty…"
      values = self.viewer.per_gaussian(step, model)
      if values is None:
        self.splat_label.content = f"no views to compute {colouring} over"
      else:
        values = np.asarray(getattr(values, SPLAT_COLOURS[colouring]))[models.live(model)]
        finite = values[np.isfinite(values)]
        hi = float(np.percentile(finite, 99)) if finite.size else 0.0
        rgb = colormap(np.nan_to_num(values), 0.0, hi if hi > 0 else 1.0).astype(
            np.float32) / 255.0
        self.splat_label.content = (f"splats coloured by {colouring}: 0 (left) to {hi:.3g} "
                                    "(right; the top 1% at the right end)")
        self.splat_bar.visible = True
    self._add("/splats", self.scene.add_gaussian_splats(
        "/splats", centers=centres, covariances=cov, rgbs=rgb, opacities=opacity))
    self.splat_key = key

  def _frustum(self, name, camera, colour, scale, visible=True):
    wxyz, position = camera_pose(camera)
    fov = 2.0 * np.arctan(0.5 * camera.height / float(np.asarray(camera.fy)))
    handle = self.scene.add_camera_frustum(
        name, fov=float(fov), aspect=camera.width / camera.height, scale=scale,
        color=tuple(int(c) for c in colour), wxyz=wxyz, position=position, visible=visible)
    return self._add(name, handle)

  def _draw_cameras(self, step):
    count = sum(len(g[1]) for g in (step.train, step.candidates) if g is not None)
    scale = (0.12 if count <= 30 else 0.06) * self.frame.radius  # many cameras: smaller
    if step.train is not None:
      cams, names = step.train
      for i in range(len(names)):
        self._clickable(self._frustum(f"/train/{i}", cams[i], TRAIN_COLOUR, scale,
                                      self.show_train.value),
                        (f"training view: {names[i]}", ("train", i)))
    scores = step.scores
    if step.candidates is not None:
      cams, names = step.candidates
      colours = np.tile(np.array(UNSCORED_COLOUR, np.uint8), (len(names), 1))
      if scores is not None:
        finite = np.isfinite(scores)
        if finite.any():
          lo, hi = float(np.min(scores[finite])), float(np.max(scores[finite]))
          colours[finite] = colormap(scores[finite], lo, hi)
          unscored = "" if finite.all() else (f"; {int((~finite).sum())} without a score, "
                                              "in grey")
          self.bar_label.content = (f"candidates coloured by {step.score_name} (as the job "
                                    f"scored them): {lo:.4g} (left) to {hi:.4g} (right)"
                                    f"{unscored}")
          self.bar.visible = True
        else:
          self.bar_label.content = f"no candidate has a finite {step.score_name}: all in grey"
      for i in range(len(names)):
        self._clickable(self._frustum(f"/candidates/{i}", cams[i], colours[i], scale,
                                      self.show_candidates.value),
                        (f"candidate: {names[i]}", ("candidates", i)))
    for p in step.proposals:
      name = f"/next/{p.rank}"
      group, index = ("candidates", p.index) if (
          p.index is not None and step.candidates is not None) else ("next", p)
      self._clickable(self._frustum(name, p.camera, NEXT_COLOUR, scale * 1.5),
                      (proposal_label(p), (group, index)))
      score = "" if p.score is None else f" ({step.score_name} {p.score:.4g})"
      self._add(f"{name}/label", self.scene.add_label(
          f"{name}/label", f"{proposal_label(p)}{score}", position=(0.0, 0.0, 0.0)))

  def _draw_lights(self, step):
    from mfsample.lighting import lights as lights_lib
    from mfsample.lighting.figures import u_over_directions

    radius = 1.4 * self.frame.radius
    self.frame.view_distance = 2.4 * radius
    if step.q is not None:
      values, dirs = u_over_directions(step.q, lights_lib.UNIFORM_NORM, 32, 64)
      lo, hi = float(values.min()), float(values.max())
      self._add("/lights/sphere", self.scene.add_point_cloud(
          "/lights/sphere", points=(self.frame.centre + radius * dirs.reshape(-1, 3)
                                    ).astype(np.float32),
          colors=colormap(values.ravel(), lo, hi), point_size=0.035 * self.frame.radius,
          point_shape="circle"))
      self.bar_label.content = (f"sphere of light directions coloured by U of a point light "
                                f"from there: {lo:.4g} (left) to {hi:.4g} (right)")
      self.bar.visible = True
    marked = list(step.lights) + ([step.next_light] if step.next_light else [])
    dirs, _ = lights_lib.direction_grid(32, 64)
    flat = dirs.reshape(-1, 3)
    for i, (label, xi) in enumerate(marked):
      brightest = flat[int(np.argmax(lights_lib.environment(xi, flat)))]
      chosen = step.next_light is not None and i == len(marked) - 1
      name = f"/lights/used/{i}"
      position = self.frame.centre + radius * 1.08 * brightest
      self._add(name, self.scene.add_point_cloud(
          name, points=np.zeros((1, 3), np.float32),
          colors=NEXT_COLOUR if chosen else TRAIN_COLOUR, point_size=0.2 * self.frame.radius,
          point_shape="circle", position=tuple(float(v) for v in position)))
      text = f"{'chosen: ' if chosen else ''}{label}"
      self._add(f"{name}/label", self.scene.add_label(f"{name}/label", text,
                                                      position=(0.0, 0.0, 0.0)))

  # ---------------------------------------------------------------- one camera

  def _clickable(self, handle, choice):
    label, target = choice
    self.cameras[label] = target

    @handle.on_click
    def _(_):
      self.camera_dropdown.value = label

  def _fill_camera_choices(self, step):
    labels = list(self.cameras)
    # The proposals first, in rank order.
    drawn = [label for label in labels if label.startswith("next view")] + [
        label for label in labels if not label.startswith("next view")]
    self.cameras = {label: self.cameras[label] for label in drawn}
    self.quiet = True
    try:
      self.camera_dropdown.options = tuple(drawn) or ("(none)",)
    finally:
      self.quiet = False
    if not drawn:
      self.camera_info.content = ""
      self.views_image.visible = False
      return
    if self.camera_dropdown.value == drawn[0]:  # unchanged: viser calls no callback
      self.show_camera(drawn[0])
    else:
      self.camera_dropdown.value = drawn[0]

  def camera_of(self, step, group, index):
    if group == "next":
      return index.camera
    cams = (step.train if group == "train" else step.candidates)[0]
    return cams[int(index)]

  def show_camera(self, label):
    """Fills the panel with the ground truth, mean render and U map of camera `label`."""
    with self.viewer.lock:
      step, choice = self.step, self.cameras.get(label)
      if step is None or choice is None:
        return
      try:
        self._show_camera(step, label, *choice)
      except Exception as e:  # noqa: BLE001 - the panel says it, the viewer stays up
        self.camera_info.content = (f"**{label}**  \nrendering it failed "
                                    f"({type(e).__name__}: {e})")
        self.views_image.visible = False

  def _show_camera(self, step, label, group, index):
    run = self.viewer.run
    camera = self.camera_of(step, group, index)
    truth = run.ground_truth(step, group, index) if group != "next" else None
    text = [f"**{label}** · {self.describe(step, group, index, label)}"]
    job_score = None
    if group == "candidates" and step.scores is not None:
      job_score = step.scores[int(index)]
    elif group == "next":
      job_score = index.score
    else:  # a proposal among unscored candidates: its own record's score
      job_score = next((p.score for p in step.proposals if group == "candidates"
                        and p.index == index), None)
    model = run.model(step)
    images, captions = [], []
    if truth is not None:
      images.append(to_uint8(truth))
      captions.append("ground truth")
    if model is None:
      text.append("no model to render for this step")
      if job_score is not None:
        text.append(f"{step.score_name} as the job scored it: {job_score:.4g}")
    else:
      self.camera_info.content = "  \n".join(text + ["rendering…"])
      rgb, pmap, u = self.viewer.renders(step, model, camera, (group, label))
      hi = float(np.nanmax(pmap)) if pmap.size and np.isfinite(pmap).any() else 0.0
      images += [to_uint8(rgb), colormap(np.nan_to_num(pmap), 0.0, hi if hi > 0 else 1.0)]
      captions += [f"mean render ({camera.width} x {camera.height})",
                   f"U map ({pmap.shape[1]} x {pmap.shape[0]}; black 0 to pale yellow "
                   f"{hi:.3g})"]
      text.append(u_line(run, step, pmap.shape, u, job_score, model))
    if images:
      self.views_image.image = views_strip(images)
      text.append(" · ".join(captions))
    self.views_image.visible = bool(images)
    self.camera_info.content = "  \n".join(text)

  def describe(self, step, group, index, label=""):
    """What the camera is: its name in the job's inputs (and its rank, when it is proposed
    and `label` does not say so)."""
    if group == "next":
      return f"a new pose{f' ({index.name})' if index.name else ''}"
    names = (step.train if group == "train" else step.candidates)[1]
    kind = "training view" if group == "train" else "candidate"
    proposal = next((p for p in step.proposals if group == "candidates" and p.index == index
                     and not label.startswith(proposal_label(p))), None)
    rank = f", {proposal_label(proposal)}" if proposal is not None else ""
    return f"{kind} {names[int(index)]}{rank}"


def proposal_label(proposal):
  """A proposal's name on screen: its rank ("next view 1" is the job's choice)."""
  return f"next view {proposal.rank}"


def u_line(run, step, size, u, job_score, model):
  """The panel's line on U of a camera: at the size the job scores at, beside the job's own
  score of it when there is one (the same definition, so the two agree)."""
  height, width = size
  num, _ = run.u_samples()
  down = run.score_downscale()
  where = (f"at {width} x {height}, 1/{down} of the image as the job scores" if down > 1
           else f"at {width} x {height}, as the job scores")
  name = "U (Eq. 10)" if not models.is_relightable(model) else "U under the step's light"
  line = f"{name} {where}, M = {num}: {u:.4g}"
  if job_score is not None:
    line += f"; {step.score_name} as the job scored it: {job_score:.4g}"
  return line


# ------------------------------------------------------------------ serving


def start(workdir, host="127.0.0.1", port=8080, wait=False):
  """Opens the run in `workdir`, starts the server and reads the run once.

  Args:
    wait: with no run in `workdir` yet (no folder, no config.json), serve a panel that
      waits for it instead of raising.

  Returns:
    the `Viewer`; its `server.get_port()` is the port bound (useful with port 0).

  Raises:
    mfsample.viewer.runs.RunError: the workdir holds no run of a known kind (without
      `wait`: nor none yet).
    ViewerError: the port is taken or the host is not an address of this machine.
  """
  import viser

  try:
    run = open_run(workdir)
  except NoRunYet:
    if not wait:
      raise
    run = None
  check_port(host, port)
  server = viser.ViserServer(host=host, port=int(port), verbose=False)
  if int(port) != 0 and server.get_port() != int(port):  # taken between the check and now
    server.stop()
    raise ViewerError(f"port {port} on {host} is in use: pass another --port, or --port=0")
  viewer = Viewer(server, workdir, run)
  viewer.refresh()
  return viewer


def serve(workdir, host="127.0.0.1", port=8080, poll_seconds=2.0, on_start=print):
  """`start` (waiting for a run not begun yet), then follows the run until interrupted
  (Ctrl-C). Nothing the workdir holds later ends it: damage is shown in the panel."""
  viewer = start(workdir, host, port, wait=True)
  shown = "localhost" if host in ("127.0.0.1", "::1", "localhost") else host
  try:
    what = KINDS[viewer.run.kind] if viewer.run else f"no run yet ({viewer.waiting})"
    on_start(f"mfsample viewer: {what} in {workdir}\n"
             f"  open http://{shown}:{viewer.server.get_port()} (bound to {host}; Ctrl-C "
             "stops)")
    while True:
      time.sleep(float(poll_seconds))
      had_run = viewer.run is not None
      viewer.refresh()
      if not had_run and viewer.run is not None:
        on_start(f"mfsample viewer: {KINDS[viewer.run.kind]} in {workdir}")
  except KeyboardInterrupt:
    pass
  finally:
    viewer.server.stop()


def screenshot(workdir, path, *, max_width=1100, size=(1280, 860), timeout=120.0, settle=10.0):
  """Saves a PNG of the viewer's page on `workdir` as headless Chromium shows it (the default
  step, its first proposal in the panel) at `path` (its folder is created), and returns the
  `Viewer` (stopped). viser fades new objects in; with WebGL in software that takes
  seconds, hence `settle`.

  Raises:
    mfsample.viewer.runs.RunError: the workdir holds no run of a known kind.
    mfsample.viewer.browser.BrowserError: no Chromium, or the page did not load in time.
  """
  from mfsample._json import atomic_path
  from mfsample.viewer.browser import Browser

  viewer = start(workdir, port=0)
  try:
    shown = default_step(viewer.steps)
    with Browser(size=size, timeout=timeout) as browser:
      browser.open(f"http://127.0.0.1:{viewer.server.get_port()}/")
      browser.wait_for_text(shown.title if shown else "mfsample")
      with atomic_path(path) as tmp:
        browser.screenshot(tmp, max_width=max_width, settle=settle)
  finally:
    viewer.server.stop()
  return viewer
