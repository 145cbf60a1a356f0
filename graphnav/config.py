"""Estimator options (``-O key=value`` on the CLI, ``**options`` in Python) -> a config dataclass."""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import fields
from typing import Any, TypeVar

T = TypeVar("T")


def config_from_options(cls: type[T], options: Mapping[str, Any], what: str) -> T:
    """``cls(**options)`` for a dataclass ``cls``; an unknown option is a ``ValueError`` naming it
    and the known ones (``what``: e.g. ``"smoother"``)."""
    known = {f.name for f in fields(cls)}  # type: ignore[arg-type]
    bad = sorted(set(options) - known)
    if bad:
        raise ValueError(f"unknown {what} option(s) {bad}; known: {sorted(known)}")
    return cls(**options)


_ROLE = re.compile(r":[a-z]+(?::[a-z]+)?:`(~?)([^`<]*?)(?:\s*<[^>]*>)?`")


def plain_text(text: str) -> str:
    """reST inline markup -> plain text (help and option descriptions): ````x```` -> x,
    ``:class:`~a.B``` -> B, ``:func:`f``` -> f, ``**b**`` -> b."""
    text = _ROLE.sub(lambda m: m.group(2).strip().rsplit(".", 1)[-1] if m.group(1) else m.group(2).strip(), text)
    return text.replace("``", "").replace("**", "")
