"""The methods Ours is compared with, used by camera planning and uncertainty quality alike.

* `fisher`: FisherRF (Jiang et al. 2024): the diagonal Fisher information of a deterministic
  model, its candidate score and its per-pixel predictive variance.
* `activenerf`: ActiveNeRF-style rendered variance (Pan et al. 2022) fitted to a
  deterministic model, its candidate score and its per-pixel map.
* `acp`: ACP (Kopanas & Drettakis 2023): coverage and angular uniformity of a camera set.
"""
