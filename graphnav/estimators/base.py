"""The estimator protocol: every estimator is a class with a ``Config`` dataclass (its ``-O`` options,
each field's help as metadata: :func:`graphnav.config.option`), ``add(record) -> Estimate | None`` and
``finish() -> RunResult``. A batch run is one loop (:func:`graphnav.estimators.run`)::

    est = Ekf(log, gate=0.99)          # options checked against Ekf.Config
    for rec in log.records:
        est.add(rec)                   # an Estimate when the estimator publishes one, else None
    result = est.finish()              # the RunResult

(:func:`graphnav.estimators.run` calls ``est.feed(log.records)``: the same loop, which an estimator may
shorten, as the graph does for runs of IMU samples.)

``online(**options)`` gives the record-by-record form live mode runs (``None``: the estimator has none).
:class:`BatchEstimator` is the form of an estimator that solves the whole log at once: ``add`` keeps the
records, ``finish`` solves them (``solve(log)``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, fields
from typing import Any, ClassVar

from ..config import config_from_options
from ..log import NavLog, Record
from ..result import Estimate, OnEstimate, OnlineEstimator, RunResult


@dataclass
class NoOptions:
    """An estimator without options."""


class Estimator:
    """One estimator. Class attributes: ``description`` (one line), ``kind`` (``"smoother"``,
    ``"filter"`` or ``"odometry"``), ``live`` (``online()`` gives a live form), ``Config`` (the options'
    dataclass; ``None``: the options go unchecked to the estimator). ``log``: the whole log when it is
    known in advance (a batch run), ``None`` online. ``options``: the options given (checked),
    ``config``: the ``Config`` they make."""

    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    kind: ClassVar[str] = "filter"
    Config: ClassVar[type | None] = NoOptions
    live: ClassVar[bool] = False  # online() gives a live form
    #: how heavy a run is beside the others' (0 a filter's light step per record, 1 a match per keyframe, 2 a
    #: factor graph, 3 a registration of every scan): compare starts its heaviest work units first
    cost: ClassVar[int] = 0
    what: ClassVar[str] = ""  # the options' name in messages ("unknown WHAT option(s)"; default: the name)

    def __init__(self, log: NavLog | None = None, *, on_estimate: OnEstimate | None = None,
                 **options: Any) -> None:
        self.log = log
        self.on_estimate = on_estimate
        self.options = dict(options)
        what = self.what or self.name or "estimator"
        self.config = None if self.Config is None else config_from_options(self.Config, options, what)

    @staticmethod
    def unmet(log: NavLog) -> str | None:
        """Why ``log`` cannot feed the estimator (``None``: it can)."""
        return None

    @staticmethod
    def inputs(log: NavLog, options: dict[str, Any]) -> Iterable[str] | None:
        """The record kinds a run on ``log`` with ``options`` reads (``None``: not declared)."""
        return None

    @classmethod
    def online(cls, **options: Any) -> OnlineEstimator | None:
        """The record-by-record form for live mode (``None``: none)."""
        return None

    @classmethod
    def option_names(cls) -> list[str]:
        return [] if cls.Config is None else [f.name for f in fields(cls.Config)]

    def add(self, record: Record) -> Estimate | None:
        raise NotImplementedError

    def feed(self, records: Sequence[Record]) -> None:
        """:meth:`add` of every record, in order (the estimates go to ``on_estimate``; an estimator may take
        runs of records at once, with the same result)."""
        for rec in records:
            self.add(rec)

    def finish(self) -> RunResult:
        raise NotImplementedError


class BatchEstimator(Estimator):
    """An estimator that solves the whole log at once: ``add`` keeps the records, ``finish`` calls
    ``solve(log)`` on them (on ``self.log`` itself when the records are exactly its records): by
    default its batch function ``batch(log, on_estimate=None, **options) -> RunResult`` with the
    options given."""

    batch: ClassVar[Callable[..., RunResult] | None] = None

    def __init__(self, log: NavLog | None = None, *, on_estimate: OnEstimate | None = None, **options: Any) -> None:
        super().__init__(log, on_estimate=on_estimate, **options)
        self._records: list[Record] = []

    def add(self, record: Record) -> None:
        self._records.append(record)
        return None

    def finish(self) -> RunResult:
        log = self.log
        if log is None or len(log.records) != len(self._records) or any(
                a is not b for a, b in zip(log.records, self._records, strict=True)):
            log = NavLog(list(self._records), list(log.beacons_known) if log else [], dict(log.meta) if log else {})
        return self.solve(log)

    def solve(self, log: NavLog) -> RunResult:
        batch = type(self).batch
        if batch is None:
            raise NotImplementedError(f"{type(self).__name__} has no batch function")
        return batch(log, on_estimate=self.on_estimate, **self.options)


RunFn = Callable[..., RunResult]


def EstimatorSpec(run: RunFn, unmet: Callable[[NavLog], str | None], description: str, kind: str = "filter",  # noqa: N802
                  inputs: Callable[[NavLog, dict[str, Any]], Iterable[str]] | None = None) -> type[BatchEstimator]:
    """An estimator class around a batch function ``run(log, on_estimate=None, **options) -> RunResult``
    (options unchecked: ``Config`` is ``None``); for estimators written as one function."""
    attrs: dict[str, Any] = {"description": description, "kind": kind, "Config": None,
                             "unmet": staticmethod(unmet), "batch": staticmethod(run)}
    if inputs is not None:
        attrs["inputs"] = staticmethod(inputs)
    return type(f"FunctionEstimator_{getattr(run, '__name__', 'run')}", (BatchEstimator,), attrs)
