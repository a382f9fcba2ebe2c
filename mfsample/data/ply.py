"""3DGS models as `.ply` files: the standard `point_cloud.ply`, read and written with `plyfile`.

The layout of the reference implementation (Kerbl et al. 2023), which other 3DGS tools and
splat viewers read and write: one binary `vertex` element, one row per Gaussian, float
properties

  x y z  nx ny nz  f_dc_0..2  f_rest_0..(3 (K - 1) - 1)  opacity  scale_0..2  rot_0..3

holding *raw* values: opacity is a logit, scales are natural logs, `rot` an unnormalised
(w, x, y, z) quaternion, colours SH coefficients (K = (degree + 1)^2, the colour is
SH(d) + 0.5) with `f_rest` channel-major (all red coefficients of bands >= 1, then green, then
blue). Normals are unused (written as zeros). These are exactly the raw groups of
`mfsample.model` (`means`, `sh_dc`, `sh_rest`, `opacity_logits`, `log_scales`, `quats`), so
a file becomes a model's mean without any conversion.

Files are written exactly as the reference code writes them: those 62 float32 properties in
that order, SH of any degree padded to degree 3 with zeros (per channel: red's 15
coefficients, then green's, then blue's), normals zero. Readers that take the header at its
word (SuperSplat, plyfile, gsplat's tools) and those that do not (the reference SIBR viewer
reads fixed records of 62 floats) see the same Gaussians. A header comment
`sh_degree D` records the model's degree, so that `load_ply` returns a degree-1 model as
degree 1 (the padding is dropped when it is all zero); readers ignore comments.

`write_gaussians_ply(..., extra=...)` appends extra float properties per Gaussian (e.g. the
uncertainty of `mfsample.gaussian_uncertainty`) after the 62: readers that go by property
name skip them (so does `load_ply`), but a fixed-record reader misreads every Gaussian after
the first. The next-views job writes its per-Gaussian uncertainty to a file of its own
(`mfsample.your_data.uncertainty_ply`) instead.

Reading accepts any SH degree 0-3 (told by the number of `f_rest_*` properties), properties
in any order and of any float type, big- or little-endian data, and ignores properties it does
not use (normals, colours of point-cloud tools, extra per-Gaussian data). It refuses, naming
the file and the property: missing properties, an `f_rest` count that is no SH degree,
non-finite values, truncated data, data after the rows the header declares (a count too
small: the rows after it would be dropped without a word), and ASCII files (3DGS tools write
binary; an ASCII file of a real model is gigabytes of text, and far more often a mesh or
point cloud saved by mistake). `read_ply_data` is the reader every `.ply` goes through
(point clouds too, where ASCII is allowed): a file is read in full or refused.
"""

import re
from pathlib import Path

import numpy as np

from mfsample._json import atomic_path
from mfsample.data._io import DatasetError, require_file

# Properties every 3DGS file has, grouped as the model's raw parameters.
_COLUMNS = {
    "means": ("x", "y", "z"),
    "sh_dc": ("f_dc_0", "f_dc_1", "f_dc_2"),
    "opacity_logits": ("opacity",),
    "log_scales": ("scale_0", "scale_1", "scale_2"),
    "quats": ("rot_0", "rot_1", "rot_2", "rot_3"),
}
# Number of f_rest properties -> SH degree: 3 channels x ((degree + 1)^2 - 1) coefficients.
_REST_COUNT = {3 * ((d + 1) ** 2 - 1): d for d in range(4)}
# The reference layout's SH degree: every file holds f_rest_0..44.
FILE_SH_DEGREE = 3
_FILE_REST = (FILE_SH_DEGREE + 1) ** 2 - 1  # coefficients per channel
# Float properties per Gaussian of the reference layout: x y z, normals, 3 + 45 SH, opacity,
# 3 scales, 4 quaternion entries.
RECORD_FLOATS = 3 + 3 + 3 * (_FILE_REST + 1) + 1 + 3 + 4
_DEGREE_COMMENT = re.compile(r"^sh_degree ([0-3])\b")


def _plyfile():
  try:
    import plyfile
  except ImportError as err:  # a core dependency; the message helps a broken environment
    raise ImportError("reading and writing .ply files needs plyfile (pip install plyfile)") \
        from err
  return plyfile


# ------------------------------------------------------------------------- writing


def ply_arrays(mean, mask=None, extra=None):
  """{property name: [N] float32} of the live rows of raw parameters `mean`, in file order:
  the reference layout's 62 properties (SH padded to degree 3 with zeros), then `extra`.

  Args:
    mean: {group: [C, ...]} raw parameters (`Model.params.mean`).
    mask: optional [C] bool; only rows where it is True are written.
    extra: optional {property name: [C] numbers} written after the standard properties
      (finite values; names other than the layout's own).
  """
  mean = {g: np.asarray(v, np.float32) for g, v in mean.items()}
  live = np.ones(len(mean["means"]), bool) if mask is None else np.asarray(mask, bool)
  n = int(live.sum())
  out = {}
  for i, axis in enumerate("xyz"):
    out[axis] = mean["means"][live, i]
  for axis in ("nx", "ny", "nz"):
    out[axis] = np.zeros(n, np.float32)
  for c in range(3):
    out[f"f_dc_{c}"] = mean["sh_dc"][live, c]
  rest = np.zeros((n, 3, _FILE_REST), np.float32)  # channel-major, padded per channel
  if "sh_rest" in mean:  # [N, K - 1, 3]
    rest[:, :, :mean["sh_rest"].shape[1]] = np.transpose(mean["sh_rest"][live], (0, 2, 1))
  rest = rest.reshape(n, -1)
  for j in range(rest.shape[1]):
    out[f"f_rest_{j}"] = rest[:, j]
  out["opacity"] = mean["opacity_logits"][live]
  for i in range(3):
    out[f"scale_{i}"] = mean["log_scales"][live, i]
  for i in range(4):
    out[f"rot_{i}"] = mean["quats"][live, i]
  for name, values in (extra or {}).items():
    values = np.asarray(values, np.float32)
    if name in out or not name.isidentifier():
      raise ValueError(f"extra property {name!r} is a property of the 3DGS layout or not a "
                       "plain name")
    if values.shape != live.shape:
      raise ValueError(f"extra property {name!r} has shape {values.shape}, expected "
                       f"{live.shape} (one value per row of the model)")
    if not np.all(np.isfinite(values[live])):
      raise ValueError(f"extra property {name!r} has non-finite values")
    out[name] = values[live]
  return out


def write_ply(path, arrays, comments=()):
  """Writes {name: [N] array} as the float32 properties of a binary little-endian `vertex`
  element (in the dict's order), with header `comments`; the file is replaced atomically."""
  plyfile = _plyfile()
  names = list(arrays)
  n = len(arrays[names[0]])
  table = np.empty(n, dtype=[(name, "<f4") for name in names])
  for name in names:
    table[name] = arrays[name]
  path = Path(path)
  with atomic_path(path) as tmp:
    plyfile.PlyData([plyfile.PlyElement.describe(table, "vertex")], byte_order="<",
                    comments=list(comments)).write(str(tmp))
  return path


def write_gaussians_ply(path, mean, mask=None, extra=None):
  """Writes raw parameters `mean` ({group: [C, ...]}, rows where `mask` is True) as a 3DGS
  file in the reference layout (`ply_arrays`), its SH degree in a header comment.

  Args:
    path: the file (replaced atomically).
    mean: raw parameters (`Model.params.mean`, `load_ply`'s output).
    mask: optional [C] bool of the rows to write.
    extra: optional {name: [C]} float properties after the 62 (see the module docstring:
      fixed-record readers then misread the file).
  """
  comment = (f"sh_degree {sh_degree_of(mean)}: f_rest beyond it are zeros "
             f"(the {RECORD_FLOATS}-float 3DGS layout)")
  return write_ply(path, ply_arrays(mean, mask, extra), comments=(comment,))


def export_ply(path, model, extra=None):
  """Writes the mean of `model` (live Gaussians only) to `path` in the 3DGS reference layout
  (`write_gaussians_ply`; `extra` float properties {name: [C]} after the standard ones)."""
  return write_gaussians_ply(path, model.params.mean, model.mask, extra)


def raw_from_gaussians(gaussians):
  """{group: [N, ...] float32} raw parameters of activated `Gaussians` (live rows only).

  The inverse of `mfsample.model.activate`: log-scales, opacity logits (opacities clipped to
  [1e-6, 1 - 1e-6] first, so both stay finite), quaternions and SH coefficients as they are.
  """
  live = (np.ones(gaussians.means.shape[0], bool) if gaussians.mask is None
          else np.asarray(gaussians.mask, bool))
  opacity = np.clip(np.asarray(gaussians.opacities, np.float64)[live], 1e-6, 1.0 - 1e-6)
  sh = np.asarray(gaussians.sh, np.float32)[live]
  raw = {"means": np.asarray(gaussians.means, np.float32)[live],
         "log_scales": np.log(np.asarray(gaussians.scales, np.float64)[live]),
         "quats": np.asarray(gaussians.quats, np.float32)[live],
         "opacity_logits": np.log(opacity) - np.log1p(-opacity),
         "sh_dc": sh[:, 0]}
  if sh.shape[1] > 1:
    raw["sh_rest"] = sh[:, 1:]
  return {g: np.asarray(v, np.float32) for g, v in raw.items()}


def export_gaussians(path, gaussians):
  """Writes activated `Gaussians` (e.g. `mfsample.testing.random_gaussians`) as a 3DGS file
  in the reference layout."""
  return write_gaussians_ply(path, raw_from_gaussians(gaussians))


# ------------------------------------------------------------------------- reading


def read_ply_data(path, *, allow_ascii=False, what=".ply file"):
  """A PLY file as `plyfile.PlyData`, read in full: every row the header declares, and
  nothing after them.

  Args:
    path: the file.
    allow_ascii: read ASCII files too (point clouds); a 3DGS model is binary.
    what: the file's role, for the message of a missing file.

  Raises:
    FileNotFoundError: no file at `path`.
    DatasetError: not a PLY file, ASCII format (unless allowed), truncated data, or data
      after the rows the header declares (the message names the file, and the element, row
      and property where known).
  """
  path = require_file(path, what)
  plyfile = _plyfile()
  size = _check_header(path, allow_ascii)
  try:
    with open(path, "rb") as f:
      # mmap=False: the data is copied (memory maps of a file stay open), and a truncated
      # file is reported with the row and property where the data ends.
      data = plyfile.PlyData.read(f, mmap=False)
      end = None if data.text else f.tell()
  except plyfile.PlyHeaderParseError as e:
    raise DatasetError(f"{path}: not a valid PLY header ({e}).") from e
  except plyfile.PlyElementParseError as e:
    raise DatasetError(f"{path}: truncated or malformed data: {e}.") from e
  except (UnicodeDecodeError, ValueError) as e:
    raise DatasetError(f"{path}: cannot be read as a PLY file ({e}).") from e
  if data.text and not allow_ascii:
    raise DatasetError(_ASCII_MESSAGE.format(path=path))
  if end is not None and end < size:  # rows of varying size (lists): known once read
    last = data.elements[-1] if data.elements else None
    raise DatasetError(f"{path}: {size - end} bytes follow the last of the "
                       f"{last.count if last else 0} {last.name if last else ''} rows the "
                       "header declares: its counts do not match the data, or the file is "
                       "corrupt.")
  return data


def read_vertex_table(path):
  """The `vertex` element of a binary PLY file as a numpy structured array (one field per
  property); the errors of `read_vertex_and_comments`."""
  return read_vertex_and_comments(path)[0]


def read_vertex_and_comments(path):
  """(the `vertex` element of a binary PLY file as a numpy structured array, [the header's
  comments]).

  Raises:
    FileNotFoundError: no file at `path`.
    DatasetError: not a PLY file, ASCII format, no `vertex` element, list properties,
      truncated data or data after the declared rows (`read_ply_data`; the message names the
      file, and the row and property where known).
  """
  plyfile = _plyfile()
  data = read_ply_data(path)
  names = [e.name for e in data.elements]
  if "vertex" not in names:
    raise DatasetError(f"{path}: no 'vertex' element (elements: {', '.join(names) or 'none'}).")
  vertex = data["vertex"]
  lists = [p.name for p in vertex.properties if isinstance(p, plyfile.PlyListProperty)]
  if lists:
    raise DatasetError(f"{path}: vertex property {lists[0]!r} is a list; a 3DGS file has "
                       "scalar properties only.")
  return vertex.data, list(data.comments)


_ASCII_MESSAGE = ("{path}: ASCII PLY; 3DGS models are binary little-endian files. Convert it "
                  "with plyfile: d = plyfile.PlyData.read(src); d.text = False; "
                  "d.byte_order = '<'; d.write(dst).")
_SCALAR_BYTES = {"char": 1, "int8": 1, "uchar": 1, "uint8": 1, "short": 2, "int16": 2,
                 "ushort": 2, "uint16": 2, "int": 4, "int32": 4, "uint": 4, "uint32": 4,
                 "float": 4, "float32": 4, "double": 8, "float64": 8}
_MAX_HEADER = 1 << 20


def _check_header(path, allow_ascii=False):
  """Checks what the header declares against the file before plyfile reads it; returns the
  file's size in bytes.

  plyfile allocates the rows an element declares before reading them, so a header that
  declares 10^11 vertices (a corrupt count, or a file cut short) asks for terabytes; and it
  stops after the declared rows, so a count too small drops the rows after it without a
  word. Here an ASCII file is refused at once (unless allowed: then it must hold exactly one
  line per declared row), and binary elements of scalar properties must fill the data that
  follows the header exactly, up to the first element with a list property (rows of varying
  size, checked after reading: `read_ply_data`). Headers this simple parser does not
  understand are left to plyfile, which reports them.
  """
  with open(path, "rb") as f:
    head = f.read(_MAX_HEADER)
    size = f.seek(0, 2)
  end = head.find(b"end_header")
  if not head.startswith(b"ply") or end < 0:
    return size
  newline = head.find(b"\n", end)
  if newline < 0:
    return size
  lines = head[:end].decode("ascii", "replace").splitlines()
  elements = []  # [name, count, [(property, bytes)], whether it has a list property]
  text = False
  for line in lines[1:]:
    words = line.split()
    if words[:1] == ["format"] and words[1:2] == ["ascii"]:
      if not allow_ascii:
        raise DatasetError(_ASCII_MESSAGE.format(path=path))
      text = True
    if words[:1] == ["element"] and len(words) == 3 and words[2].isdigit():
      elements.append([words[1], int(words[2]), [], False])
    elif words[:1] == ["property"] and elements:
      if words[1:2] == ["list"] and len(words) == 5 and words[2] in _SCALAR_BYTES:
        elements[-1][2].append((words[4], _SCALAR_BYTES[words[2]]))  # at least its length
        elements[-1][3] = True
      elif len(words) == 3 and words[1] in _SCALAR_BYTES:
        elements[-1][2].append((words[2], _SCALAR_BYTES[words[1]]))
      else:
        return size  # a header plyfile will report
  if text:
    _check_text_rows(path, newline + 1, elements)
    return size
  left = size - (newline + 1)
  for name, count, properties, has_list in elements:
    row = sum(b for _, b in properties)  # the exact row size, or a lower bound with lists
    if count * row > left:
      r, offset = divmod(left, row) if row else (0, 0)
      at = next((p for p, end in _ends(properties) if end > offset), name)
      raise DatasetError(f"{path}: truncated: the header declares {count} {name} rows of "
                         f"{'at least ' if has_list else ''}{row} bytes, but the data ends "
                         f"in row {r}, at property {at!r} ({left} bytes of data).")
    if has_list:
      return size  # rows vary in size from here on: plyfile reads them one by one
    left -= count * row
  if left > 0 and elements:
    name, count, properties, _ = elements[-1]
    row = sum(b for _, b in properties)
    rows = (f" (the size of {left / row:.3g} row{'' if left == row else 's'} of {row} bytes)"
            if row else "")
    raise DatasetError(f"{path}: {left} bytes follow the last of the {count} {name} rows the "
                       f"header declares{rows}: its counts do not match the data, or the "
                       "file is corrupt.")
  return size


def _check_text_rows(path, start, elements):
  """An ASCII PLY holds one line per row (plyfile reads them so): the non-blank lines after
  the header must number the rows the header declares."""
  with open(path, "rb") as f:
    f.seek(start)
    found = sum(1 for line in f if line.strip())
  declared = sum(count for _, count, _, _ in elements)
  if found != declared:
    counts = ", ".join(f"{count} {name}" for name, count, _, _ in elements) or "none"
    raise DatasetError(f"{path}: the header declares {declared} rows ({counts}), but the "
                       f"data holds {found} lines (an ASCII PLY holds one line per row): "
                       + ("truncated." if found < declared else "its counts do not match the "
                          "data, or the file is corrupt."))


def _ends(properties):
  """(name, byte offset of its end within the row) of each property."""
  end = 0
  for name, b in properties:
    end += b
    yield name, end


def load_ply(path):
  """The raw parameters of a 3DGS `.ply` file (see the module docstring for the layout).

  Args:
    path: a `point_cloud.ply` written by the 3DGS reference code, gsplat, nerfstudio's
      splatfacto export, `export_ply`, or any tool using the same layout.

  Returns:
    {group: float32 numpy array}: `means` [N, 3], `log_scales` [N, 3], `quats` [N, 4],
    `opacity_logits` [N], `sh_dc` [N, 3] and, for SH degree > 0, `sh_rest` [N, K - 1, 3]
    (K = (degree + 1)^2), exactly as stored (the model's raw groups: `init_model`'s mean,
    `mfsample.model.model_from_mean`). The degree is told by the number of `f_rest_*`
    properties, or by the `sh_degree D` comment that mfsample's writer leaves when the
    bands above D are all zero.

  Raises:
    FileNotFoundError: no file at `path`.
    DatasetError: the problems listed in the module docstring, naming the file and the
      property.
  """
  table, comments = read_vertex_and_comments(path)
  present = set(table.dtype.names)
  for group, columns in _COLUMNS.items():
    missing = [c for c in columns if c not in present]
    if missing:
      raise DatasetError(f"{path}: missing vertex propert{'ies' if len(missing) > 1 else 'y'} "
                         f"{', '.join(missing)} (the 3DGS layout needs {', '.join(columns)} for "
                         f"{group}).")
  n = len(table)
  if n == 0:
    raise DatasetError(f"{path}: the vertex element has no rows (no Gaussians).")
  out = {group: _stack(table, columns, path) for group, columns in _COLUMNS.items()}
  out["opacity_logits"] = out["opacity_logits"][:, 0]
  rest = sorted((p for p in present if p.startswith("f_rest_")), key=lambda p: (len(p), p))
  if rest:
    if len(rest) not in _REST_COUNT:
      raise DatasetError(f"{path}: {len(rest)} f_rest_* properties; an SH degree of 1, 2 or 3 "
                         f"has {', '.join(str(c) for c in sorted(_REST_COUNT)[1:])}.")
    expected = [f"f_rest_{j}" for j in range(len(rest))]
    missing = [p for p in expected if p not in present]
    if missing:
      raise DatasetError(f"{path}: missing vertex property {missing[0]} (f_rest_* must be "
                         f"numbered 0..{len(rest) - 1}).")
    values = _stack(table, expected, path)  # channel-major: [N, 3, K - 1]
    rest = np.transpose(values.reshape(n, 3, len(rest) // 3), (0, 2, 1))
    written = next((int(m.group(1)) for m in map(_DEGREE_COMMENT.match, comments) if m), None)
    if written is not None and written < _REST_COUNT[3 * rest.shape[1]]:
      kept = (written + 1) ** 2 - 1  # the padding of a lower-degree model, when all zero
      if not np.any(rest[:, kept:]):
        rest = rest[:, :kept]
    if rest.shape[1]:
      out["sh_rest"] = np.ascontiguousarray(rest)
  return out


def sh_degree_of(mean):
  """SH degree of raw parameters `mean` (0 without `sh_rest`)."""
  rest = mean.get("sh_rest")
  return 0 if rest is None else int(round(np.sqrt(rest.shape[1] + 1))) - 1


def _stack(table, columns, path):
  """[N, len(columns)] float32 from named columns; DatasetError naming a bad one."""
  out = np.empty((len(table), len(columns)), np.float32)
  for j, name in enumerate(columns):
    column = table[name]
    if not np.issubdtype(column.dtype, np.floating):
      raise DatasetError(f"{path}: vertex property {name} has type {column.dtype}; 3DGS "
                         "stores floats.")
    out[:, j] = column
    bad = ~np.isfinite(out[:, j])
    if np.any(bad):
      raise DatasetError(f"{path}: vertex property {name} is not finite in row "
                         f"{int(np.argmax(bad))} ({int(bad.sum())} rows in all).")
  return out
