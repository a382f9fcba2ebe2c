"""The parameter groups a model may hold, in the canonical order of a flattened vector.

A model's raw parameters are a dict of groups, each an array [C, ...] with one row per
Gaussian (`mfsample.model`). The order below is the one every per-Gaussian flattening follows
(the diagonal sampler's z, densification, exports), so it is defined once, here.
"""

# 3DGS with SH colour. `sh_rest` exists only when the model's SH degree is above 0.
GROUPS = ("means", "log_scales", "quats", "opacity_logits", "sh_dc", "sh_rest")
# The relightable field's groups (`mfsample.lighting`): per-Gaussian transfer matrices in place
# of SH colour, split like the SH colour into the outgoing DC row and the other rows (their own
# learning rates).
TRANSFER_GROUPS = ("transfer_dc", "transfer_rest")
# Every group a model may hold, in the canonical order.
GROUP_ORDER = GROUPS + TRANSFER_GROUPS


def ordered(groups):
  """`groups` (any iterable of known group names) in the canonical order."""
  return sorted(groups, key=GROUP_ORDER.index)
