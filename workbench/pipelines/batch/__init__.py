"""Batch studies: a manifest of jobs (``manifest``), each row one job run on a local pool or a
dask.distributed cluster, with resumable markers and logs (``run``), and each row's key figures
(``figures``).

A row runs the job's function as the command line registers it (option checking included),
which calls the job's pipeline; its figures come back as values, not from its printed output.
May import: core, model, io, services, reporting and the other pipelines.
"""
