"""twinbench: the digital twin of a powertrain test bench, from Python.

A thin layer over the same Rust libraries as the ``twinbench`` command line:

- :func:`run` runs a system file (TOML or SSP) and returns a :class:`Result` whose
  ``signals`` map ``instance.variable`` names to numpy arrays;
- :func:`compare` compares a result with a vehicle measurement on a distance basis
  (the paper's m, R², e, and the bias);
- :class:`Study` runs an optimisation study, on this machine's threads or on any
  ``concurrent.futures.Executor`` (a Dask cluster's ``Client.get_executor()``), and
  offers the ask/tell steps for an optimiser of your own.

The simulations release the GIL. Every error is a :class:`TwinbenchError` with the
command line's message.
"""

from __future__ import annotations

import json
import math
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _native
from ._native import TwinbenchError, __version__


class TwinbenchWarning(UserWarning):
    """A warning of twinbench's own code (a repaired store folder, a candidate's failed
    run, a best point whose re-evaluation differs): every one the command line prints."""


def _forward_warnings(fn):
    """After the call, every warning the Rust code gave during it as a ``TwinbenchWarning``."""
    import functools

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        finally:
            for message in _native.take_warnings():
                warnings.warn(message, TwinbenchWarning, stacklevel=3)

    return wrapper


def _threads(threads) -> int:
    """``threads`` as the native calls take it (0: all cores), or a TwinbenchError naming it
    (a negative count was a bare OverflowError from the conversion)."""
    if threads is None:
        return 0
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 0:
        raise TwinbenchError(f"threads={threads!r}: a number of threads, 0 or more (0 or None: all cores)")
    return threads

__all__ = [
    "__version__",
    "run",
    "pack",
    "realtime_check",
    "compare",
    "Result",
    "Comparison",
    "Metrics",
    "Study",
    "StudyStep",
    "StudyResult",
    "Optimizer",
    "TwinbenchError",
    "TwinbenchWarning",
]

PathLike = Union[str, "os.PathLike[str]"]


@dataclass
class Result:
    """A simulation's recording and summary.

    Attributes:
        signals: ``instance.variable`` (and ``time``) → numpy float64 array, in the
            recorded order, the exact values the command line writes with ``--out``.
        units: the unit of each signal (``""`` when it has none).
        text: the recorded String signals, name → list of str.
        summary: steps, simulated_time [s], wall_time [s], lap_time [s] (or None),
            stopped_by, reported (name → value at the end), order (stepping order),
            warnings.
    """

    signals: Dict[str, np.ndarray]
    units: Dict[str, str]
    summary: Dict[str, Any]
    text: Dict[str, List[str]] = field(default_factory=dict)

    def to_pandas(self):
        """The signals as a pandas DataFrame indexed by ``time``.

        Needs pandas: ``pip install 'twinbench[pandas]'`` (or ``pip install pandas``).
        """
        try:
            import pandas as pd
        except ImportError:
            raise ImportError(
                "Result.to_pandas() needs pandas, which is not installed: "
                "pip install 'twinbench[pandas]' (or pip install pandas)"
            ) from None

        frame = pd.DataFrame({k: v for k, v in self.signals.items() if k != "time"})
        if "time" in self.signals:
            frame.index = pd.Index(self.signals["time"], name="time")
        for name, values in self.text.items():
            frame[name] = values
        return frame

    def __repr__(self) -> str:
        s = self.summary
        return (
            f"Result({len(self.signals)} signals, {len(next(iter(self.signals.values()), []))} rows, "
            f"simulated {s.get('simulated_time', 0):.3f} s, stopped by {s.get('stopped_by')!r})"
        )


@_forward_warnings
def pack(out: Optional[PathLike] = None, models: Optional[Sequence[str]] = None) -> List[Path]:
    """Pack twinbench's FMUs, as ``twinbench pack`` does.

    Args:
        out: the folder to write them into (default: ``$XDG_DATA_HOME/twinbench/fmu``,
            that is ``~/.local/share/twinbench/fmu``, the command line's).
        models: the models to pack (default: ``vehicle``, ``driver``, ``dyno``, ``edu``).

    Returns:
        The paths of the FMUs written.

    Raises:
        TwinbenchError: an unknown model, a folder that cannot be written.
    """
    written = _native.pack(None if out is None else os.fspath(out), None if models is None else list(models))
    return [Path(p) for p in written]


def _worker_executable(executable: Optional[PathLike]) -> str:
    """The twinbench executable a check's worker runs: given, else $TWINBENCH_WORKER_EXE,
    else `twinbench` on the PATH."""
    import shutil

    found = executable or os.environ.get("TWINBENCH_WORKER_EXE") or shutil.which("twinbench")
    if not found:
        raise TwinbenchError(
            "realtime_check runs the FMU in a worker that is the twinbench executable (it "
            "counts the allocations); none was found: pass executable=, set "
            "TWINBENCH_WORKER_EXE, or put twinbench on the PATH (cargo install --path .)"
        )
    return os.fspath(found)


@_forward_warnings
def realtime_check(
    fmu: PathLike,
    step: Optional[float] = None,
    duration: Optional[float] = None,
    input: Optional[PathLike] = None,
    passes: int = 10,
    budget: Optional[float] = None,
    instructions: bool = False,
    isolate: str = "confined",
    timeout: float = 600.0,
    preload: Sequence[PathLike] = (),
    executable: Optional[PathLike] = None,
) -> Union[Dict[str, Any], List[Dict[str, Any]]]:
    """Whether an FMU is fit for a real-time target, as ``twinbench realtime-check`` says.

    After initialisation the FMU is stepped in an isolated worker; each step's FMI calls
    (inputs set, ``doStep``, outputs read) are watched for allocations, locks, log
    messages and system calls (each by name), and timed.

    Args:
        fmu: an FMU (FMI 2.0 or 3.0 Co-Simulation), or a bench's system file (``.toml``):
            then every FMU of the bench with the inputs its first instance has on the
            bench's run.
        step: the communication step [s] (default: the FMU's default experiment's, else
            1e-3; a bench's own step).
        duration: simulated time of one pass [s].
        input: CSV or MDF 4 file of the inputs over time (columns named as the FMU's Real
            inputs).
        passes: passes over the duration (the instance reset between them).
        budget: the longest step allowed [s] (without it the step's time is measured, not
            judged).
        instructions: also count ``doStep``'s instructions per step under callgrind.
        isolate: ``"confined"`` (default) or ``"crash-only"``.
        timeout: the longest the whole check may take [s].
        preload: libraries the worker loads before the FMU's (libpython for pythonfmu).
        executable: the twinbench executable the worker runs (default:
            ``$TWINBENCH_WORKER_EXE``, else ``twinbench`` on the PATH).

    Returns:
        The report (``items`` with each verdict, ``clean``, the ``measurement``), or for a
        bench a list of ``{"instance": ..., "report": ...}``.

    Raises:
        TwinbenchError: an FMU that cannot be checked, a bad input file or option.
    """
    worker = _worker_executable(executable)
    text = _native.realtime_check(
        os.fspath(fmu),
        worker,
        step,
        duration,
        None if input is None else os.fspath(input),
        passes,
        budget,
        instructions,
        isolate,
        timeout,
        [os.fspath(p) for p in preload],
    )
    return json.loads(text)


@_forward_warnings
def run(
    system: PathLike,
    parameters: Optional[Mapping[str, Union[float, int, bool, str]]] = None,
    stop: Optional[Union[float, str]] = None,
    observer: Optional[Callable[[float, Dict[str, Union[float, str]]], Any]] = None,
    every: Optional[float] = None,
) -> Result:
    """Run a system file and return its recording.

    Args:
        system: the system description (TOML), an SSP 1.0 package (``.ssp``), or one FMU
            (``.fmu``, run on its own as ``twinbench run model.fmu`` runs it: its default
            experiment, every output, named by the FMU's own variables).
        parameters: ``{"instance.variable": value}``, as ``twinbench run --set`` (checked
            against the variable's type and range before the run).
        stop: a stop time in s, or a condition such as ``"vehicle.lap >= 1"``; None keeps
            the system file's.
        observer: watches the run while it goes on (a live plot, a progress display, a
            condition of your own): called as ``observer(time, values)``, ``values`` the
            recorded signals' values at that time (``{"vehicle.v": 31.2, ...}``), at the
            start, every ``every`` s of simulated time and at the end. It returns None or
            True to go on, False or a reason (a str, the summary's ``stopped_by``) to end
            the run there; an exception fails the run and is raised as itself.
        every: how often the observer is called, in s of simulated time (rounded to whole
            steps); default: at each recorded row.

    Returns:
        A :class:`Result`: ``result.signals["vehicle.v"]`` is a numpy array.

    Raises:
        TwinbenchError: a bad system file, a wrong name or value, a failed run (the
            message is the command line's).
    """
    items = list((parameters or {}).items())
    raw = _native.run(os.fspath(system), items, stop, observer, every)
    names = raw["names"]
    units = raw["units"] or [""] * len(names)
    signals = {
        name: np.frombuffer(col, dtype="<f8").copy() for name, col in zip(names, raw["columns"])
    }
    text = dict(raw["text"])
    for name in text:
        signals.pop(name, None)
    summary = dict(raw["summary"])
    summary["reported"] = dict(summary["reported"])
    return Result(signals=signals, units=dict(zip(names, units)), summary=summary, text=text)


@dataclass(frozen=True)
class Metrics:
    """One signal's agreement on the distance grid (paper §4.2).

    ``m`` slope and ``intercept`` of simulated on measured, ``r_squared`` R², ``e`` Eq. 16
    ((1 − R²)/2 + |m − 1|/2), ``bias`` mean(sim − meas)/mean(meas), ``rms`` in the
    signal's unit, ``points`` compared.
    """

    m: float
    intercept: float
    r_squared: float
    e: float
    bias: float
    rms: float
    points: int


@dataclass(frozen=True)
class Comparison:
    """A comparison: ``signals`` name → :class:`Metrics`, the distance range [m] and the
    coverage (fraction of the measured distance the simulation covers)."""

    signals: Dict[str, Metrics]
    distance_range: Tuple[float, float]
    coverage: float

    def __getitem__(self, signal: str) -> Metrics:
        return self.signals[signal]


@_forward_warnings
def compare(
    result: Union[Result, Mapping[str, Sequence[float]]],
    measurement: PathLike,
    signals: Union[str, Sequence[str]] = ("Fz_sum",),
    cutoff_hz: float = 2.0,
    filter_order: int = 2,
    distance_step_m: float = 1.0,
    min_coverage: float = 0.9,
    channels: Optional[PathLike] = None,
) -> Comparison:
    """Compare a simulation with a vehicle measurement on a distance basis.

    As ``twinbench compare``: both are low-pass filtered alike (zero-phase Butterworth)
    and resampled on a distance grid; per signal the regression slope m, R², e and the
    bias.

    Args:
        result: a :class:`Result`, or a mapping of column name → values (``time`` and a
            distance or speed column, and the signals).
        measurement: the measurement file, CSV or MDF 4.
        signals: the signals to compare (a name or a list; derived: Fz_sum, Fz_front,
            Fz_rear).
        cutoff_hz: the filter's cutoff [Hz].
        filter_order: Butterworth order of one pass.
        distance_step_m: the distance grid's step [m].
        min_coverage: least fraction of the measured distance the simulation must cover.
        channels: a TOML file mapping signals to the measurement's own channel names.

    Raises:
        TwinbenchError: a missing signal, a bad file, too little coverage.
    """
    columns = result.signals if isinstance(result, Result) else result
    names = list(columns.keys())
    data = [np.ascontiguousarray(columns[n], dtype="<f8").tobytes() for n in names]
    if isinstance(signals, str):
        signals = [s for s in signals.split(",")]
    import json

    raw = json.loads(
        _native.compare(
            names,
            data,
            os.fspath(measurement),
            list(signals),
            float(cutoff_hz),
            int(filter_order),
            float(distance_step_m),
            float(min_coverage),
            None if channels is None else os.fspath(channels),
        )
    )
    metrics = {
        s["signal"]: Metrics(
            m=s["slope"],
            intercept=s["intercept"],
            r_squared=s["r_squared"],
            e=s["e"],
            bias=s["bias"],
            rms=s["rms"],
            points=s["points"],
        )
        for s in raw["signals"]
    }
    return Comparison(
        signals=metrics,
        distance_range=tuple(raw["distance_range_m"]),
        coverage=raw["coverage"],
    )


class Optimizer:
    """One of twinbench's optimisers (``"ga"`` or ``"cmaes"``), ask/tell, in the
    parameters' own units.

    >>> opt = Optimizer("cmaes", bounds=[(0.5, 1.5), (0.5, 1.5)], seed=1)
    >>> xs = opt.ask()                     # a generation, each within the bounds
    >>> opt.tell([f(x) for x in xs])       # their costs, in the same order

    ``best()`` is the best candidate so far and its cost; ``save()``/``restore()`` carry
    the whole state (bit-exact) for a checkpoint.
    """

    def __init__(
        self,
        kind: str,
        bounds: Sequence[Tuple[float, float]],
        seed: int = 0,
        start: Optional[Sequence[float]] = None,
    ):
        self._inner = _native.OptimizerPy(
            kind, [tuple(map(float, b)) for b in bounds], int(seed), None if start is None else list(start)
        )

    def ask(self) -> List[List[float]]:
        """The next generation's candidates."""
        return self._inner.ask()

    def tell(self, costs: Sequence[float]) -> None:
        """The costs of the last ``ask``'s candidates, in its order (lower is better)."""
        self._inner.tell([float(c) for c in costs])

    def best(self) -> Optional[Tuple[List[float], float]]:
        """The best candidate so far and its cost (None before the first ``tell``)."""
        return self._inner.best()

    @property
    def generation(self) -> int:
        """Completed generations."""
        return self._inner.generation

    def save(self) -> str:
        """The whole state as JSON."""
        return self._inner.save()

    def restore(self, state: str) -> None:
        """Continue from ``save()``'s JSON."""
        self._inner.restore(state)


class StudyResult(dict):
    """A study's result (a dict, as ``twinbench optimize --json`` prints it) that knows its
    ``result.json`` (``path``) and hands the fitted twin on."""

    path: Path

    def export_twin(self, out: PathLike, fmi: Sequence[int] = (2, 3)) -> Dict[str, Any]:
        """Write the fitted twin into the folder ``out``, as ``twinbench export-twin``:
        ``fmu/<instance>.fmu`` (and ``-fmi3.fmu``) whose start values are the answer,
        ``fitted_system.toml``, ``fitted_twin.ssp``, ``fitted_twin.ssv``,
        ``parameters.csv``/``.json`` and ``provenance.json``.

        Args:
            out: a new folder, or an earlier export's.
            fmi: the FMI versions of the fitted FMUs (2, 3 or both).

        Returns:
            The summary: ``folder``, ``files``, ``fitted_instances``,
            ``copied_instances`` (a supplier's FMUs, copied as they are), ``notes``.

        Raises:
            TwinbenchError: the result's FMUs are from another build, the folder holds
                other files, a file it names cannot be read.
        """
        import json

        return json.loads(_native.export_twin(os.fspath(self.path), os.fspath(out), [int(v) for v in fmi]))


@dataclass(frozen=True)
class StudyStep:
    """A step of a study: its parameters, their bounds and start values (None: the
    value before the step)."""

    index: int
    name: str
    parameters: List[str]
    bounds: List[Tuple[float, float]]
    start: List[Optional[float]]


class Study:
    """An optimisation study file (``twinbench optimize``'s input).

    >>> study = Study("studies/spielberg.toml")
    >>> result = study.optimize()                            # this machine's threads
    >>> result = study.optimize(executor=client.get_executor())   # a Dask cluster

    For an optimiser of your own, :meth:`evaluate` gives the costs of candidates of a
    step (on threads or an executor), and :class:`Optimizer` twinbench's own ask/tell.
    """

    @_forward_warnings
    def __init__(self, path: PathLike):
        self.path = Path(path).absolute()
        (
            self.name,
            self.system,
            self.measurement,
            self.fingerprint,
            self.penalty,
            self.seed,
        ) = _native.load_study(os.fspath(self.path))
        self._evaluator = None
        # Per Dask client: the executor that sends this study's files (see _shipping).
        self._shipped = {}

    def __repr__(self) -> str:
        return f"Study({str(self.path)!r}, name={self.name!r})"

    def _loaded(self):
        # The bench (FMUs unpacked, measurement read) only when candidates are evaluated.
        if self._evaluator is None:
            self._evaluator = _native.StudyEvaluatorPy(os.fspath(self.path))
        return self._evaluator

    def _shipping(self, executor):
        """`executor`, or for a Dask cluster's the one that sends this study's files by
        content: made once per cluster, its files taken off the cluster when this Study
        is gone."""
        from . import _shipping

        client = _shipping.dask_client(executor)
        if client is None:
            return executor
        key = id(client)
        shipped = self._shipped.get(key)
        if shipped is None or shipped.client is not client:
            import weakref

            shipped = _shipping.shipping(executor, os.fspath(self.path), self._loaded())
            self._shipped[key] = shipped
            weakref.finalize(self, shipped.close)
        return shipped

    @property
    def steps(self) -> List[StudyStep]:
        """The study's steps, in order."""
        return [
            StudyStep(k, name, list(params), [tuple(b) for b in bounds], list(start))
            for k, (name, params, bounds, start) in enumerate(self._loaded().steps())
        ]

    def assignment(self) -> Dict[str, float]:
        """Every parameter the study touches, with its value before the study."""
        return dict(self._loaded().assignment())

    @_forward_warnings
    def optimize(
        self,
        executor: Any = None,
        threads: Optional[int] = None,
        resume: bool = False,
        generations: Optional[int] = None,
        optimizer: Optional[str] = None,
        out: Optional[PathLike] = None,
        force: bool = False,
        report: bool = True,
        progress: Optional[Callable[[Dict[str, Any]], None]] = None,
        profiles: bool = False,
        bootstrap: int = 0,
    ) -> Dict[str, Any]:
        """Run the study, as ``twinbench optimize --json``, and return its result.

        Writes the same files (checkpoint after every generation, ``result.json``,
        ``table1.json``, the report) into ``out``.

        Args:
            executor: a ``concurrent.futures.Executor`` for the generations' candidates,
                one task per candidate (Dask: ``Client.get_executor()``), and for the
                joint fit after the steps (refinement, profiles) one task per point.
                Every worker process needs twinbench installed; on a Dask cluster the
                study's files travel with the tasks by content (no shared disk needed),
                with another executor they are read at the same paths. A worker loads
                the study once and keeps it. None: this process's threads.
            threads: threads for the local runs (all of them without an executor: the
                generations and the joint fit; with one: the start, identifiability and
                result runs).
                None: all cores.
            resume: continue from the checkpoint in ``out`` (same result as an
                uninterrupted run, wherever the candidates ran).
            generations: override every step's generations.
            optimizer: override the study's optimiser, ``"ga"`` or ``"cmaes"``.
            out: output folder (default ``target/optimize``, as the command line).
            force: optimise even when the measurement and the twin do not belong together.
            report: write Tab. 1 and the plots.
            progress: called after every generation with a dict (``phase``:
                ``"generation"``, step, 1-based, step_name, generations, generation,
                evaluations, best_cost, best_x, failures, and workers: this process's
                threads, or on a Dask cluster the workers it has now). An exception it
                raises stops the study after that generation, its checkpoint kept, and is
                raised. After the steps, the joint refinement, the profiles and the
                bootstrap send a record per batch of laps: ``phase`` (``"refinement"``,
                ``"profiles"``, ``"bootstrap"``), ``parameters`` (their names), ``laps``
                (so far in the phase), ``seconds`` and ``done`` (the phase's last record);
                an exception raised for one of those is raised when the study returns.
                A callback that reads a generation's fields checks ``record["phase"] ==
                "generation"`` first.
            profiles: profile likelihood of every parameter after the joint refinement
                (as ``--profiles``); the intervals are then the profiles'.
            bootstrap: refits of a moving-block bootstrap of the answer (as
                ``--bootstrap N``; 0: none); ``result["joint"]["bootstrap"]`` then has
                each parameter's bootstrap ``std_error``, its ``ratio`` to the sandwich's
                and a percentile ``interval``.

        Returns:
            The result as a dict (per step: parameters before/after, e before/after,
            history, identifiability; ``joint``: the study's answer, all parameters
            refined together, with the intervals; ``joint_intervals``; ``profiles`` when
            asked for), and ``"parameters"``: each fitted parameter by name with its
            ``value`` (the study's answer), ``unit``, ``interval`` (``[lo, hi]``, ``None``
            for an open end; ``None`` when there is none), ``interval_method``,
            ``interval_statement`` (why an interval is open or missing), ``std_error``
            and ``interval_with_model`` (the interval that adds what the twin cannot
            represent of this car: the one to quote when the model check finds a
            discrepancy); and ``"model_check"``: ``discrepancy`` (True: the twin cannot
            represent this lap within its noise), ``statistic``, ``p_value``, ``method``,
            ``detail`` (the verdict in words).

        Raises:
            TwinbenchError: a bad study, system or measurement; a checkpoint of other
                options; files that differ on a worker.
        """
        import json

        function = signals = digest = None
        if executor is not None:
            from . import _worker

            function, signals = _worker.cost, _worker.signals
            digest = self._loaded().digest
            # A Dask cluster's workers get the study's files with the tasks.
            executor = self._shipping(executor)
        text = _native.optimize(
            os.fspath(self.path),
            os.fspath(out if out is not None else "target/optimize"),
            _threads(threads),
            bool(resume),
            generations,
            optimizer,
            bool(force),
            not report,
            executor,
            function,
            digest,
            progress,
            bool(profiles),
            signals,
            int(bootstrap),
        )
        result = StudyResult(json.loads(text))
        result.path = Path(os.fspath(out if out is not None else "target/optimize")) / "result.json"
        # The study's answer (Tab. 1's row "all"): every parameter with its interval; a
        # result without one (written before it was made) gives each step's own.
        joint = result.get("joint")
        rows = joint["parameters"] if joint else [p for s in result["steps"] for p in s["parameters"]]
        result["parameters"] = {
            p["name"]: {
                "value": p["after"],
                "unit": p.get("unit"),
                "interval": list(p["interval"]) if p.get("interval") is not None else None,
                "interval_method": p.get("interval_method"),
                "interval_statement": p.get("interval_statement"),
                "std_error": p.get("std_error"),
                "interval_with_model": list(p["interval_with_model"])
                if p.get("interval_with_model") is not None
                else None,
            }
            for p in rows
        }
        # Whether the twin, not the noise, limits the answer (None where it could not be
        # made, or the result is older than the check).
        result["model_check"] = joint.get("model_check") if joint else None
        return result

    @_forward_warnings
    def evaluate(
        self,
        step: int,
        candidates: Sequence[Sequence[float]],
        values: Optional[Mapping[str, float]] = None,
        executor: Any = None,
        threads: Optional[int] = None,
        penalty: Optional[float] = None,
    ) -> List[float]:
        """The costs of candidates of one step, for an optimiser of your own.

        Args:
            step: the step (0-based) whose signals and weights make the cost.
            candidates: values of the step's parameters (``steps[step].parameters``
                order), one list per candidate.
            values: the other parameters' values (default: before the study; pass the
                earlier steps' results here).
            executor: a ``concurrent.futures.Executor`` (one task per candidate); None:
                ``threads`` threads here.
            penalty: the cost of a candidate whose run fails (default: the study's);
                its reason is given as a warning.

        Returns:
            One cost per candidate, in order, the same bits wherever it ran.
        """
        loaded = self._loaded()
        base = dict(loaded.assignment())
        names = list(base)
        if values:
            unknown = [k for k in values if k not in base]
            if unknown:
                raise TwinbenchError(
                    f"{self.path}: values for parameters the study does not touch: {', '.join(unknown)} (it touches {', '.join(names)})"
                )
            base.update({k: float(v) for k, v in values.items()})
        steps = self.steps
        if not 0 <= step < len(steps):
            raise TwinbenchError(f"{self.path}: step {step} (the study has {len(steps)} steps, 0-based)")
        params = steps[step].parameters
        full = []
        for k, x in enumerate(candidates):
            x = [float(v) for v in x]
            if len(x) != len(params):
                raise TwinbenchError(
                    f"candidate {k} has {len(x)} values for the {len(params)} parameters of step '{steps[step].name}' ({', '.join(params)})"
                )
            v = dict(base)
            v.update(zip(params, x))
            full.append([v[n] for n in names])
        if executor is None:
            results = loaded.costs(step, full, _threads(threads))
        else:
            from . import _shipping, _worker

            # A Dask cluster's workers get the study's files with the tasks, published
            # once for every call on that cluster while this Study lives.
            shipped = self._shipping(executor)
            futures = [
                shipped.submit(_worker.cost, os.fspath(self.path), loaded.digest, step, v)
                for v in full
            ]
            results = [f.result() for f in futures]
        penalty = self.penalty if penalty is None else float(penalty)
        if not (math.isfinite(penalty) and penalty >= 0.0):
            raise TwinbenchError(f"penalty = {penalty!r}: a cost, a finite number >= 0")
        costs = []
        for k, r in enumerate(results):
            if isinstance(r, str):
                warnings.warn(f"candidate {k} failed (cost {penalty}): {r}", stacklevel=2)
                costs.append(penalty)
            else:
                costs.append(float(r))
        return costs
