"""Batch. Batch studies: manifests (``manifest``), many cases on a local pool or a
dask.distributed cluster with resumable markers and logs (``run``), and the study's figures
(``figures``).

May import: core, model, io, and any capability package it runs.
"""
