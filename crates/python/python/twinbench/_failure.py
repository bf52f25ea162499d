"""Why a candidate's run failed, as a task returns it: a ``str`` (its message, what the
study reports and scripts match) that also carries the failure's kind (``kind``: ``fmu``,
``worker``, ``simulation``, ``setting``, ``comparison``, ...), so that the coordinator of a
distributed study gets back the kind the worker's error had. A plain ``str`` from a task
of the caller's own is a failure of kind ``unknown``.
"""

from __future__ import annotations


class Failure(str):
    """A failed run's message (this str) with its kind (``kind``)."""

    kind: str

    def __new__(cls, message: str, kind: str = "unknown") -> "Failure":
        self = super().__new__(cls, message)
        self.kind = kind
        return self

    def __reduce__(self):
        # Pickled as its message and kind (a Dask task's result crosses processes so).
        return (Failure, (str(self), self.kind))
