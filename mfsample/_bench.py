"""Pieces shared by the scripts in `benchmarks/`: the machine record and the data hint.

Every benchmark JSON carries `machine()`, so the table built from it can state the hardware
and the JAX version it was measured with.
"""

import os
import platform

NERF_SYNTHETIC_HINT = (
    "NeRF Synthetic is linked from the NeRF project page "
    "(https://www.matthewtancik.com/nerf): download nerf_synthetic.zip from its Google Drive "
    "folder, unzip it, and point {flag} at the lego folder (default: "
    "data/nerf_synthetic/lego, relative to the working directory).")


def machine():
  """{platform, processor, cpu_count, backend, device_kind, device_count, jax}.

  Initialises JAX's backend: a caller that must not hold the accelerator (a parent whose
  children measure) calls it after them.
  """
  import jax

  device = jax.devices()[0]
  return {"platform": platform.platform(), "processor": platform.machine(),
          "cpu_count": os.cpu_count(), "backend": jax.default_backend(),
          "device_kind": device.device_kind, "device_count": jax.device_count(),
          "jax": jax.__version__}


def require_scene_folder(path, flag):
  """Raises FileNotFoundError naming `flag`, `path` and where to get NeRF Synthetic when
  `path` holds no `transforms_train.json`."""
  if not os.path.isfile(os.path.join(path, "transforms_train.json")):
    raise FileNotFoundError(f"no NeRF Synthetic scene at {flag}={path!r} (no "
                            f"transforms_train.json there). "
                            + NERF_SYNTHETIC_HINT.format(flag=flag))


def load_average():
  """(1, 5, 15)-minute load averages, NaN where the platform has none."""
  try:
    return os.getloadavg()
  except OSError:
    return (float("nan"),) * 3
