"""What runs on a worker process of a distributed study (a Dask worker, a process pool).

Each task is one candidate, ``cost(study, digest, step, values)``, or one point of the
joint fit (the refinement and the profiles after the steps), ``signals(study, digest,
values)``. ``study`` is the study's path (a process pool, a shared file system) or, on a
Dask cluster, its shipment: its files named by content, which the worker keeps in its own
store and fetches through Dask when it lacks one (``_shipping``). The first task of a
study loads it (FMUs unpacked, measurement read) and the process keeps it for every later
task, so a worker pays the start-up once. The coordinator's ``digest`` (SHA-256 of every
file the study reads) must match this worker's files: a worker that sees other files
refuses, naming the file, rather than computing a cost of another study.
"""

from __future__ import annotations

import threading
from typing import Dict, List, Tuple, Union

from . import _native, _shipping
from ._native import TwinbenchError

_lock = threading.Lock()
_loaded: Dict[str, "_native.StudyEvaluatorPy"] = {}
_points = 0


def _evaluator(study, digest: str):
    study = _shipping.study_path(study)
    with _lock:
        ev = _loaded.get(study)
        if ev is not None and ev.digest == digest:
            return ev
        # New to this process, or its files changed since: (re)load from disk.
        ev = _native.StudyEvaluatorPy(study)
        _loaded[study] = ev
    if ev.digest != digest:
        why = ev.mismatch(digest) or "the study's files differ from the coordinator's"
        raise TwinbenchError(f"{study} on this worker: {why}")
    return ev


def cost(study, digest: str, step: int, values: List[float]) -> Union[float, str]:
    """The candidate's cost (a float), or the reason its run failed (a str: the study
    penalises it and goes on). Raises when the worker cannot evaluate at all."""
    return _evaluator(study, digest).cost(step, values)


def signals(study, digest: str, values: List[float]) -> Union[List[Tuple[int, bytes]], str]:
    """One point of the study's joint fit (its refinement, a profile): every fitted lap
    run with ``values`` (every parameter), and per lap and signal the first grid index and
    the filtered signal on the grid as little-endian float64 bytes; or the reason the run
    failed (a str). Raises when the worker cannot evaluate at all."""
    global _points
    ev = _evaluator(study, digest)
    with _lock:
        _points += 1
    return ev.signals(values)


def loaded() -> int:
    """Studies this process holds (for tests and diagnostics)."""
    with _lock:
        return len(_loaded)


def points() -> int:
    """Points of joint fits this process has run (for tests and diagnostics)."""
    with _lock:
        return _points
