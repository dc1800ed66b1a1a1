"""Dask worker plugin of the studies' ``LocalCluster`` (imported only when Dask is used)."""

from __future__ import annotations

from distributed.diagnostics.plugin import WorkerPlugin

__all__ = ["ParentWatch"]


class ParentWatch(WorkerPlugin):
    """The LocalCluster's worker processes die with the process that started the study
    (:func:`lightcurve.process.watch_parent`)."""

    def __init__(self, pid: int):
        self.pid = int(pid)

    def setup(self, worker=None):
        from ..process import watch_parent

        watch_parent(self.pid, pdeathsig=False)
