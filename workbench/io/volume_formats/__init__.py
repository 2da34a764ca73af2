"""Readers for 3-D medical image formats; use :func:`workbench.io.volumes.read_volume`."""
