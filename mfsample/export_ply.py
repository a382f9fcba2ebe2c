"""Export of the mean model in the standard 3DGS `.ply` layout.

One binary little-endian `vertex` element with float32 properties, in this order (the
layout of the reference implementation, which common splat viewers read):

  x y z nx ny nz f_dc_0..2 f_rest_0..(3(K-1)-1) opacity scale_0..2 rot_0..3

Values are *raw*: opacity is a logit, scales are logs, rotations are unnormalised
(w, x, y, z) quaternions, colours are SH coefficients with `f_rest` ordered channel-major
(all red coefficients, then green, then blue). Normals are zero. Only live Gaussians are
written; `f_rest` is absent for SH degree 0.
"""

import numpy as np


def ply_arrays(mean, mask=None):
  """{property name: [N] float32} of the live rows of raw parameters `mean`."""
  mean = {g: np.asarray(v, np.float32) for g, v in mean.items()}
  live = np.ones(len(mean["means"]), bool) if mask is None else np.asarray(mask, bool)
  out = {}
  for i, axis in enumerate("xyz"):
    out[axis] = mean["means"][live, i]
  for axis in ("nx", "ny", "nz"):
    out[axis] = np.zeros(int(live.sum()), np.float32)
  for c in range(3):
    out[f"f_dc_{c}"] = mean["sh_dc"][live, c]
  if "sh_rest" in mean:
    rest = np.transpose(mean["sh_rest"][live], (0, 2, 1)).reshape(int(live.sum()), -1)
    for j in range(rest.shape[1]):
      out[f"f_rest_{j}"] = rest[:, j]
  out["opacity"] = mean["opacity_logits"][live]
  for i in range(3):
    out[f"scale_{i}"] = mean["log_scales"][live, i]
  for i in range(4):
    out[f"rot_{i}"] = mean["quats"][live, i]
  return out


def export_ply(path, model):
  """Writes the mean of `model` (an `mfsample.model.Model`) to `path` in the 3DGS layout."""
  write_ply(path, ply_arrays(model.params.mean, model.mask))


def write_ply(path, arrays):
  """Writes {name: [N] float32} as a binary little-endian PLY `vertex` element."""
  names = list(arrays)
  n = len(arrays[names[0]])
  header = ["ply", "format binary_little_endian 1.0", f"element vertex {n}"]
  header += [f"property float {name}" for name in names]
  header += ["end_header"]
  table = np.empty(n, dtype=[(name, "<f4") for name in names])
  for name in names:
    table[name] = arrays[name]
  with open(path, "wb") as f:
    f.write(("\n".join(header) + "\n").encode("ascii"))
    f.write(table.tobytes())


def read_ply(path):
  """Reads a PLY written by `write_ply` (binary little-endian float vertices)."""
  with open(path, "rb") as f:
    names, n = [], None
    if f.readline().strip() != b"ply":
      raise ValueError(f"{path} is not a PLY file")
    while True:
      raw = f.readline()
      if not raw:
        raise ValueError(f"{path}: truncated PLY header")
      line = raw.decode("ascii").strip()
      if line.startswith("format") and "binary_little_endian" not in line:
        raise ValueError(f"unsupported PLY format: {line}")
      if line.startswith("element vertex"):
        n = int(line.split()[-1])
      elif line.startswith("property float"):
        names.append(line.split()[-1])
      elif line == "end_header":
        break
    table = np.frombuffer(f.read(), dtype=[(name, "<f4") for name in names], count=n)
  return {name: np.array(table[name]) for name in names}
