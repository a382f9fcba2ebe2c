"""Datasets: posed images with the camera conventions of `mfsample.camera`."""

from mfsample.data.views import Views

__all__ = ["Views"]
