"""What the NMEA 0183 sentence decoders share: the output (:class:`NmeaParse`), the per-sentence
context (:class:`DecodeContext`: counters, why a sentence gave nothing, lenient optional fields,
the plausibility limits) and the snapshot/restore of a decoder part's state (:class:`Stateful`)."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Any, ClassVar

from ..errors import LogError
from ..log import Limits, Record, default_limits


@dataclass
class NmeaParse:
    """Everything a stream of sentences gave: records, SOG/COG samples and counters."""

    records: list[Record] = field(default_factory=list)
    sog_cog: list[tuple[float, float, float]] = field(default_factory=list)  # (t, sog m/s, cog deg | nan)
    counts: Counter = field(default_factory=Counter)


class Stateful:
    """A decoder part whose attributes named in ``STATE`` are all a sentence can change (scalars,
    tuples, immutable frames): :meth:`snapshot` saves them, :meth:`restore` puts them back."""

    STATE: ClassVar[tuple[str, ...]] = ()

    def snapshot(self) -> tuple[Any, ...]:
        return tuple(getattr(self, k) for k in self.STATE)

    def restore(self, state: tuple[Any, ...]) -> None:
        for k, v in zip(self.STATE, state, strict=True):
            setattr(self, k, v)


class DecodeContext(Stateful):
    """The decoder's output and per-sentence bookkeeping, shared by its parts.

    ``keep`` (file reader) collects records and SOG/COG samples in ``out``; without (live mode)
    memory stays flat. ``keep_sog_cog=False`` counts the SOG/COG samples without holding them.
    ``drop_bad_fields`` (lenient): a bad optional field is dropped, the sentence kept. ``why``: why the
    current sentence gave nothing (None: it was read)."""

    STATE = ("why",)

    def __init__(self, *, keep: bool, keep_sog_cog: bool, limits: Limits | None, drop_bad_fields: bool) -> None:
        self.out = NmeaParse()
        self.keep, self.keep_sog_cog = keep, keep_sog_cog
        self.limits = limits  # physical validity of every record (graphnav.log.check_record)
        self.drop_bad_fields = drop_bad_fields
        self.why: str | None = None

    @property
    def counts(self) -> Counter:
        return self.out.counts

    def optional(self, parse: Any, *args: Any, **kw: Any) -> Any:
        """An optional field parsed by ``parse``: its value, or (``drop_bad_fields``) None when it is
        bad, counted per field in ``dropped_field:<name>`` (the sentence is kept)."""
        try:
            return parse(*args, **kw)
        except LogError as err:
            if not self.drop_bad_fields:
                raise
            self.out.counts["dropped_field:" + (err.field or "?")] += 1
            return None

    def skip(self, reason: str, counter: str | None = None) -> list[Record]:
        """Nothing from this sentence, for ``reason`` (in ``meta["sentences"]``); ``counter`` also
        counts it under that name (the older per-reason meta keys)."""
        self.why = reason
        if counter:
            self.out.counts[counter] += 1
        return []

    def speed_value(self, v: float, name: str, unit: float) -> float:
        """A speed field's value [field unit] -> m/s, checked against the plausible speed
        (:class:`graphnav.log.Limits`)."""
        top = (self.limits or default_limits()).max_speed
        if v * unit > top:
            raise LogError(f"speed {v * unit:.4g} m/s beyond the plausible limit {top:g} m/s", field=name)
        return v * unit
