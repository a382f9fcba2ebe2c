"""The device check: the renderer and a training step at real size, in one command.

  python benchmarks/gpu_check.py --garden=PATH/test_garden.npz --out=DIR

It measures, part by part (--parts, in order), and writes DIR/gpu_check.json and
DIR/gpu_check.md after every part, so a run cut short still leaves what it had measured:

  WORKLOAD/COMPOSITOR[:FIELD=VALUE...]  a render. WORKLOAD: garden (gsplat's garden points
      at 648 x 420, SH degree 3, gsplat's random scales, rotations and opacities:
      `mfsample._workloads.garden`, from --garden or its generated stand-in) or 50k400
      (50,000 random Gaussians at 400 x 400, `benchmarks/render.py`'s cell). Settings:
      `RenderSettings(compositor=COMPOSITOR, FIELD=VALUE, ...)` with the power-of-two budget
      training would grow to. Figures (`mfsample._bench.time_render`): forward and
      forward+backward ms (medians of --repeats calls after a warm-up, each blocked on),
      forward+backward ms when the calls are queued back to back (pipelined), tile
      intersections, budget, the device allocator's peak memory, XLA's memory for the
      compiled forward+backward, and the part's seconds (compilation included).
  overhead  the timing loop's own floor: a jitted call that takes the garden's Gaussians and
      camera (the render's arguments) and returns one number, timed as the renders are
      (each call blocked on) and queued back to back. A render figure near it measures
      dispatch, not work.
  reference  the jnp compositor on the CPU (JAX_PLATFORMS=cpu) for every workload of the
      render parts, in the background beside the other parts (on half of the CPUs). Every
      render part's image and gradients (w.r.t. every Gaussian parameter and the camera)
      are compared with it: a numerical fault of the device cannot hide.
  step/COMPOSITOR[@C]  a training step at --step_size from --step_points points (rank 2,
      M = 1; C chunks per compositing step), `benchmarks/train_step.py --render_share`: its
      median ms, the renderer's forward+backward alone, and the share of the step outside it.
      Lego at --data, or its synthetic stand-in.

Each part runs in a fresh process: its peak memory is its own, and a crash (or a GPU
context a kernel fault poisoned) loses that part only; a failed part is recorded with the
end of its error output and the next one runs. The parent process never initialises JAX,
so it holds no device memory. --time_budget_s bounds the whole run: a part starts only if
the time left is at least what the longest part of its kind took so far, and a part still
running at the limit is stopped and recorded as such. The defaults run the core parts
first, then variants of the settings, most telling first, as far as the budget goes.

--tiny shrinks every workload (the garden to 1/64 of its points at 1/8 of its size, 500
Gaussians at 48 x 48, a 50 x 50 step from 300 points), so the same command runs on a CPU;
its times mean nothing:

  python benchmarks/gpu_check.py --tiny --parts=reference,garden/jnp --repeats=2
"""

import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time

from absl import app, flags

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
WORKLOADS = ("garden", "50k400")
REFERENCE = "reference"
OVERHEAD = "overhead"
# The core figures first (the reference runs beside them, on the CPU), then variants of the
# settings on the same workloads, most telling first: the jnp loop without its per-step
# host round trip and in fewer, larger steps; the kernel's block width and warp count.
DEFAULT_PARTS = (
    REFERENCE, OVERHEAD, "garden/jnp", "garden/pallas", "50k400/jnp", "50k400/pallas",
    "step/jnp", "step/pallas",
    "garden/jnp:chunks_per_step=256:skip_unused_steps=False",
    "garden/pallas:chunk_size=16",
    "garden/jnp:skip_unused_steps=False",
    "garden/pallas:pallas_warps=4",
    "step/jnp@256",
    "garden/pallas:chunk_size=16:pallas_warps=4",
    "50k400/jnp:chunks_per_step=256:skip_unused_steps=False",
    "garden/jnp:chunks_per_step=256",
    "garden/pallas:chunk_size=64",
)
# Below this many seconds left, no part starts (a JAX process takes seconds to start).
MIN_PART_SECONDS = 10.0

_GARDEN = flags.DEFINE_string(
    "garden", "", "gsplat's test_garden.npz (default: a generated stand-in with the same "
    "statistics, whose tile intersections differ from the real garden's).")
_OUT = flags.DEFINE_string("out", "workdirs/benchmarks/gpu_check",
                           "Folder of gpu_check.json and gpu_check.md.")
_PARTS = flags.DEFINE_list("parts", list(DEFAULT_PARTS), "Parts to run, in order.")
_REPEATS = flags.DEFINE_integer("repeats", 10, "Timed calls per figure (median).")
_BUDGET = flags.DEFINE_float("time_budget_s", 450.0,
                             "Seconds for the whole run; later parts are skipped.")
_TINY = flags.DEFINE_bool("tiny", False, "Shrink every workload (a CPU smoke run).")
_DATA = flags.DEFINE_string("data", "data/nerf_synthetic/lego",
                            "step: NeRF Synthetic lego (400 x 400 files); synthetic if absent.")
_STEP_SIZE = flags.DEFINE_integer("step_size", 400, "step: image side in pixels.")
_STEP_POINTS = flags.DEFINE_integer("step_points", 100_000, "step: initial points.")
_CHILD = flags.DEFINE_string("child", None, "Internal: run this part and print its result.")
_SCRATCH = flags.DEFINE_string("scratch", None, "Internal: folder of the compared outputs.")


# ----------------------------------------------------------------------------- parts


def parse_part(spec):
  """"garden/pallas:chunk_size=16" -> ("garden", "pallas", {"chunk_size": 16}).

  Fields are separated by ":" (--parts is a comma-separated list). Values are read as
  Python literals where they are one (16, 0.5, True), else as strings.
  "step/jnp@256" -> ("step", "jnp", {"chunks_per_step": 256}).
  """
  import ast

  head, *fields = spec.split(":")
  workload, slash, compositor = head.partition("/")
  if not slash or workload not in (*WORKLOADS, "step"):
    raise ValueError(f"part {spec!r}: expected WORKLOAD/COMPOSITOR[:FIELD=VALUE...] with "
                     f"WORKLOAD one of {(*WORKLOADS, 'step')}, or {REFERENCE!r}")
  compositor, at, chunks = compositor.partition("@")
  overrides = {}
  if at:
    overrides["chunks_per_step"] = int(chunks)
  for item in fields:
    name, eq, value = item.partition("=")
    if not eq:
      raise ValueError(f"part {spec!r}: {item!r} is not FIELD=VALUE")
    try:
      overrides[name] = ast.literal_eval(value)
    except (ValueError, SyntaxError):
      overrides[name] = value
  return workload, compositor, overrides


def load_workload(name, garden, tiny):
  """The `mfsample._workloads.Workload` of a render part."""
  from mfsample import _workloads

  if name == "garden":
    return _workloads.garden(garden, shrink=8 if tiny else 1)
  return _workloads.random_cell(500, 48) if tiny else _workloads.random_cell(50_000, 400)


def _save_outputs(path, timing):
  """The timed render's image and float gradients, as numpy, for the comparison."""
  import jax
  import numpy as np

  arrays = {"rgb": np.asarray(timing.rgb), "alpha": np.asarray(timing.alpha)}
  for key, leaf in jax.tree_util.tree_flatten_with_path(timing.grads)[0]:
    leaf = np.asarray(leaf)
    if np.issubdtype(leaf.dtype, np.floating):
      arrays["grad" + jax.tree_util.keystr(key)] = leaf
  np.savez(path, **arrays)


def run_render(spec, *, garden, tiny, repeats, scratch):
  """One render part in this process: its figures (the outputs go to `scratch`)."""
  from mfsample import RenderSettings
  from mfsample._bench import device_memory_mb, fitted_settings, peak_rss_mb, time_render

  workload, compositor, overrides = parse_part(spec)
  gaussians, camera, source = load_workload(workload, garden, tiny)
  settings = RenderSettings.holding(1, compositor=compositor, **overrides)
  settings = fitted_settings(gaussians, camera, settings)
  timing = time_render(gaussians, camera, settings, repeats=repeats, pipelined=True)
  _save_outputs(os.path.join(scratch, _file_name(spec)), timing)
  peak, limit = device_memory_mb()
  return {"workload": workload, "source": source, "compositor": compositor,
          "overrides": overrides, "num_gaussians": gaussians.num_gaussians,
          "image": [camera.width, camera.height], "repeats": repeats, **timing.figures,
          "device_peak_mb": peak, "device_limit_mb": limit, "peak_rss_mb": peak_rss_mb()}


def run_reference(workloads, *, garden, tiny, scratch):
  """The jnp compositor on this process's device (the CPU) for every workload."""
  from mfsample import RenderSettings
  from mfsample._bench import fitted_settings, time_render

  figures = {}
  for name in workloads:
    gaussians, camera, _ = load_workload(name, garden, tiny)
    settings = fitted_settings(gaussians, camera, RenderSettings())
    timing = time_render(gaussians, camera, settings, repeats=1)
    _save_outputs(os.path.join(scratch, _file_name(f"{REFERENCE}_{name}")), timing)
    figures[name] = {"forward_ms": timing.figures["forward_ms"],
                     "forward_backward_ms": timing.figures["forward_backward_ms"],
                     "intersections": timing.figures["intersections"]}
  return {"workloads": figures}


def run_overhead(*, garden, tiny, repeats):
  """The timing loop's floor on this device: `median_ms` and `pipelined_ms` of a jitted
  call with the render's arguments (the garden's Gaussians and camera) and a scalar out."""
  import jax
  import jax.numpy as jnp

  from mfsample._bench import median_ms, pipelined_ms

  gaussians, camera, _ = load_workload("garden", garden, tiny)
  touch = jax.jit(lambda g, cam: jnp.sum(g.opacities[:1]) + cam.fx)
  call = lambda: touch(gaussians, camera)
  blocked_ms, _ = median_ms(call, repeats)
  return {"call_ms": blocked_ms, "call_pipelined_ms": pipelined_ms(call, repeats),
          "repeats": repeats}


def _file_name(spec):
  return "".join(c if c.isalnum() else "_" for c in spec) + ".npz"


def compare_outputs(got_path, want_path):
  """Differences of a part's outputs from the reference's.

  Returns:
    {image_max_abs_diff (rgb and alpha), image_mean_abs_diff, grad_max_rel_diff (max over
    gradient leaves of max |got - want| / max |want|), grad_rel_l2_diff (max over leaves of
    ||got - want|| / ||want||), grads: {leaf: [rel max, rel l2]}}.
  """
  import numpy as np

  with np.load(got_path) as got, np.load(want_path) as want:
    images = [np.abs(got[k] - want[k]) for k in ("rgb", "alpha")]
    grads = {}
    for key in want.files:
      if key.startswith("grad"):
        g, w = got[key].astype(np.float64), want[key].astype(np.float64)
        scale, norm = max(np.abs(w).max(), 1e-30), max(np.linalg.norm(w), 1e-30)
        grads[key[4:]] = [float(np.abs(g - w).max() / scale),
                          float(np.linalg.norm(g - w) / norm)]
  return {"image_max_abs_diff": float(max(d.max() for d in images)),
          "image_mean_abs_diff": float(np.mean([d.mean() for d in images])),
          "grad_max_rel_diff": max((v[0] for v in grads.values()), default=None),
          "grad_rel_l2_diff": max((v[1] for v in grads.values()), default=None),
          "grads": grads}


def step_command(spec, *, data, size, points, steps, repeats_warmup=2):
  """The `benchmarks/train_step.py` child command of a step part."""
  _, compositor, overrides = parse_part(spec)
  unknown = set(overrides) - {"chunks_per_step"}
  if unknown:
    raise ValueError(f"part {spec!r}: a step takes only @C (chunks per step), not {unknown}")
  variant = "rank2" + (f"@{overrides['chunks_per_step']}" if overrides else "")
  return [sys.executable, os.path.join(ROOT, "benchmarks", "train_step.py"),
          f"--child={variant}", f"--compositor={compositor}", f"--size={size}",
          f"--points={points}", "--samples=1", f"--steps={steps}",
          f"--warmup={repeats_warmup}", f"--data={data}", "--render_share",
          "--fit_start_budget"]


# ----------------------------------------------------------------------------- the report


def write_report(out, record):
  """DIR/gpu_check.json and DIR/gpu_check.md, atomically."""
  from mfsample._json import write_json, write_text

  write_json(os.path.join(out, "gpu_check.json"), record)
  write_text(os.path.join(out, "gpu_check.md"), markdown(record))


def _fmt(value, spec):
  return "-" if value is None else format(value, spec)


def markdown(record):
  """The report as markdown tables: renders, CPU comparison, steps, and the other parts."""
  machine = record.get("machine") or {}
  parts = record["parts"]
  done = sum(p["status"] != "pending" for p in parts)
  lines = [f"# Device check: {machine.get('device_kind', 'device unknown')} "
           f"({machine.get('backend', '-')}), JAX {machine.get('jax', '-')}", "",
           f"Status: {record['status']}, {done} of {len(parts)} parts; "
           f"{record['seconds']:.0f} s. Command: `{record['command']}`", "",
           "| part | N | image | intersections | budget | fwd ms | fwd+bwd ms "
           "| pipelined fwd+bwd ms | device peak MB | XLA fwd+bwd MB | image diff vs CPU "
           "| grad rel L2 diff | s |",
           "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
  for p in parts:
    if p["status"] == "ok" and "forward_ms" in p:
      lines.append(
          f"| {p['part']} | {p['num_gaussians']} | {p['image'][0]}x{p['image'][1]} "
          f"| {p['intersections']} | {p['budget']} | {p['forward_ms']:.2f} "
          f"| {p['forward_backward_ms']:.2f} | {_fmt(p['forward_backward_pipelined_ms'], '.2f')} "
          f"| {_fmt(p['device_peak_mb'], '.0f')} | {_fmt(p['xla_backward_mb'], '.0f')} "
          f"| {_fmt(p.get('image_max_abs_diff'), '.1e')} "
          f"| {_fmt(p.get('grad_rel_l2_diff'), '.1e')} | {p['seconds']:.0f} |")
  for p in parts:
    if p["status"] == "ok" and "call_ms" in p:
      lines += ["", f"Timing floor ({p['part']}): {p['call_ms']:.3f} ms a call blocked on, "
                f"{p['call_pipelined_ms']:.3f} ms a call queued back to back."]
  steps = [p for p in parts if p["status"] == "ok" and "ms_median" in p]
  if steps:
    lines += ["", "| part | scene | N | image | step ms | renderer fwd+bwd ms "
              "| outside the renderer | device peak MB | s |",
              "|---|---|---:|---|---:|---:|---:|---:|---:|"]
    for p in steps:
      lines.append(
          f"| {p['part']} | {p['scene']} | {p['live']} | {p['resolution']}^2 "
          f"| {p['ms_median']:.1f} | {p['render_forward_backward_ms']:.1f} "
          f"| {p['outside_renderer_share']:.0%} | {_fmt(p['device_peak_mb'], '.0f')} "
          f"| {p['seconds']:.0f} |")
  others = [p for p in parts if p["status"] != "ok"]
  if others:
    lines += ["", "| part | status | note |", "|---|---|---|"]
    for p in others:
      note = " ".join(str(p.get("error", "")).split())[-300:].replace("|", "/")
      lines.append(f"| {p['part']} | {p['status']} | {note} |")
  return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- the parent


def _child_env(cpu=False):
  env = dict(os.environ, PYTHONPATH=os.pathsep.join(
      [ROOT, *filter(None, [os.environ.get("PYTHONPATH")])]))
  if cpu:
    env["JAX_PLATFORMS"] = "cpu"
  return env


def _part_command(spec, scratch):
  """(command line, whether it runs on the CPU) of a part's child process."""
  if _kind(spec) == "step":
    tiny = _TINY.value
    return step_command(spec, data=os.path.abspath(_DATA.value),
                        size=50 if tiny else _STEP_SIZE.value,
                        points=300 if tiny else _STEP_POINTS.value,
                        steps=3 if tiny else _REPEATS.value), False
  garden = os.path.abspath(_GARDEN.value) if _GARDEN.value else ""
  return [sys.executable, os.path.abspath(__file__), f"--child={spec}", f"--garden={garden}",
          f"--tiny={_TINY.value}", f"--repeats={_REPEATS.value}", f"--scratch={scratch}",
          f"--parts={','.join(_PARTS.value)}"], spec == REFERENCE


class _Child:
  """A part's child process. Its output goes to files in `scratch` (a pipe nobody reads
  while it runs could fill up and stall it)."""

  def __init__(self, spec, command, cpu, scratch, cpus=None):
    self.spec, self.start, self.stopped = spec, time.perf_counter(), False
    name = os.path.join(scratch, _file_name(spec)[:-len(".npz")])
    self.paths = (name + ".stdout", name + ".stderr")
    pin = None
    if cpus and hasattr(os, "sched_setaffinity"):
      pin = lambda: os.sched_setaffinity(0, cpus)
    with open(self.paths[0], "w") as out, open(self.paths[1], "w") as err:
      self.proc = subprocess.Popen(command, stdout=out, stderr=err, env=_child_env(cpu),
                                   cwd=ROOT, preexec_fn=pin)

  def wait(self, timeout):
    """Whether the child ended within `timeout` seconds."""
    try:
      self.proc.wait(timeout=max(timeout, 0.0))
      return True
    except subprocess.TimeoutExpired:
      return False

  def stop(self):
    self.stopped = True
    self.proc.kill()
    self.proc.wait()

  def outcome(self):
    """(status, result dict or None, error text) of the ended child."""
    with open(self.paths[0]) as out, open(self.paths[1]) as err:
      stdout, stderr = out.read(), err.read()
    lines = stdout.strip().splitlines()
    if self.stopped:
      return "stopped at the time budget", None, stderr[-2000:]
    if self.proc.returncode or not lines:
      return "failed", None, (f"exit status {self.proc.returncode}: "
                              + (stderr[-2000:] or stdout[-2000:]))
    last = lines[-1]
    return "ok", json.loads(last[len("RESULT "):] if last.startswith("RESULT ") else last), ""


def _half_of_the_cpus():
  """The upper half of this process's CPUs (None below four): the background CPU reference
  runs there, leaving the rest to the process that drives the GPU."""
  if not hasattr(os, "sched_getaffinity"):
    return None
  cpus = sorted(os.sched_getaffinity(0))
  return set(cpus[len(cpus) // 2:]) if len(cpus) >= 4 else None


def _kind(spec):
  return spec.split(":")[0].split("/")[0].split("@")[0]


def _compare_pending(parts, scratch):
  """Adds the comparison with the reference to every render part that has both outputs."""
  for p in parts:
    if p["status"] != "ok" or "forward_ms" not in p or "image_max_abs_diff" in p:
      continue
    got = os.path.join(scratch, _file_name(p["part"]))
    want = os.path.join(scratch, _file_name(f"{REFERENCE}_{p['workload']}"))
    if os.path.exists(got) and os.path.exists(want):
      p.update(compare_outputs(got, want))


def run_all(out, parts, budget_s, scratch, command_of):
  """Runs `parts` in child processes within `budget_s` seconds; returns the record.

  The reference part, which runs on the CPU, starts first and runs beside the others (on
  half of the CPUs where there are four or more); the others run one after the other.

  command_of: part -> (command line, whether it runs on the CPU) of its child, which prints
  its result as JSON on its last line (after "RESULT ", optionally).
  """
  start = time.perf_counter()
  left = lambda: budget_s - (time.perf_counter() - start)
  record = {"command": " ".join(["python", "benchmarks/gpu_check.py", *sys.argv[1:]]),
            "host": platform.node(), "started": time.strftime("%Y-%m-%d %H:%M:%S"),
            "status": "running", "seconds": 0.0, "time_budget_s": budget_s, "machine": None,
            "parts": [{"part": spec, "status": "pending"} for spec in parts]}
  entries = {entry["part"]: entry for entry in record["parts"]}

  def launch(spec, cpus=None):
    try:
      return _Child(spec, *command_of(spec), scratch, cpus)
    except Exception as e:  # noqa: BLE001 -- a bad part must not stop the others
      finish(spec, ("failed", None, f"{type(e).__name__}: {e}"), 0.0)
      return None

  def finish(spec, outcome, seconds):
    status, result, error = outcome
    entry = entries[spec]
    entry.update(status=status, seconds=seconds)
    if result:
      record["machine"] = result.pop("machine", None) or record["machine"]
      entry.update(result)
    if error:
      entry["error"] = error
    _compare_pending(record["parts"], scratch)
    record["seconds"] = time.perf_counter() - start
    write_report(out, record)
    print(f"[gpu_check] {spec}: {status} in {seconds:.0f} s"
          + (f"\n{error[-1000:]}" if status != "ok" else ""), flush=True)

  def collect(child, timeout):
    """Waits up to `timeout` s for `child` (stops it then) and records its outcome."""
    if not child.wait(timeout):
      child.stop()
    finish(child.spec, child.outcome(), time.perf_counter() - child.start)

  write_report(out, record)
  reference = None
  if REFERENCE in entries and left() >= MIN_PART_SECONDS:
    print(f"[gpu_check] {REFERENCE} (in the background) ...", flush=True)
    reference = launch(REFERENCE, _half_of_the_cpus())
    entries[REFERENCE]["status"] = "running" if reference else entries[REFERENCE]["status"]
  longest = {}  # the longest duration so far of each kind of part
  for spec in parts:
    if spec == REFERENCE:
      continue
    if reference and reference.wait(0):
      collect(reference, 0)
      reference = None
    if left() < max(MIN_PART_SECONDS, longest.get(_kind(spec), 0.0)):
      entries[spec].update(status="skipped", error=f"{left():.0f} s of the time budget left")
      continue
    print(f"[gpu_check] {spec} ({left():.0f} s left) ...", flush=True)
    child = launch(spec)
    if child:
      collect(child, left())
      longest[_kind(spec)] = max(longest.get(_kind(spec), 0.0), entries[spec]["seconds"])
  if reference:
    collect(reference, left())
  for entry in record["parts"]:
    if entry["status"] == "pending":
      entry.update(status="skipped", error="no time budget left")
  record["status"] = "complete"
  record["seconds"] = time.perf_counter() - start
  write_report(out, record)
  return record


def _child_main(spec):
  from mfsample._bench import machine

  kwargs = dict(garden=_GARDEN.value, tiny=_TINY.value, scratch=_SCRATCH.value)
  if spec == REFERENCE:
    render_parts = [p for p in _PARTS.value if _kind(p) in WORKLOADS]
    workloads = sorted({parse_part(p)[0] for p in render_parts})
    result = run_reference(workloads, **kwargs)
  elif spec == OVERHEAD:
    result = run_overhead(garden=_GARDEN.value, tiny=_TINY.value, repeats=_REPEATS.value)
  else:
    result = run_render(spec, repeats=_REPEATS.value, **kwargs)
  result["machine"] = machine()
  print("RESULT " + json.dumps(result), flush=True)


def main(argv):
  del argv
  if _CHILD.value:
    _child_main(_CHILD.value)
    return
  if _GARDEN.value and not os.path.isfile(_GARDEN.value):
    raise SystemExit(f"--garden={_GARDEN.value!r}: no such file (gsplat's "
                     "assets/test_garden.npz; leave --garden out for a generated stand-in)")
  os.makedirs(_OUT.value, exist_ok=True)
  scratch = tempfile.mkdtemp(prefix="gpu_check_")
  try:
    record = run_all(_OUT.value, _PARTS.value, _BUDGET.value, scratch,
                     lambda spec: _part_command(spec, scratch))
  finally:
    shutil.rmtree(scratch, ignore_errors=True)
  print()
  print(markdown(record))
  print(f"saved {os.path.join(_OUT.value, 'gpu_check.json')} and gpu_check.md")


if __name__ == "__main__":
  sys.path.insert(0, ROOT)
  app.run(main)
