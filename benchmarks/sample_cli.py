"""Sample where one graphnav CLI command spends its CPU, without cProfile's per-call distortion.

    python benchmarks/sample_cli.py OUT.txt -- run data/harbour.npz -e isam2 --json
    python benchmarks/sample_cli.py OUT.txt --tree builder.py:step --depth 3 -- run data/harbour.npz -e isam2

A ``SIGPROF`` timer fires every millisecond of the process's CPU time and records the Python stack
(``file:function`` frames); each sample is weighted by the CPU time since the previous one, so time spent
inside a C++ call (GTSAM, a numba kernel) is charged to the Python frame that made the call, and the
weights add up to the command's CPU seconds. cProfile instead charges every Python call a fixed
overhead: it showed the record bookkeeping of the harbour run as a third of the time (docs/performance.md).
OUT.txt gets the CPU seconds, the top functions inclusive and by own time, and with ``--tree FUNC`` the
tree of calls under ``FUNC``.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import io
import os
import signal
import sys
import time
from pathlib import Path
from types import FrameType

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from graphnav import cli  # noqa: E402

Stack = tuple[str, ...]


class Sampler:
    """CPU-time weighted stack samples of this process."""

    def __init__(self, interval: float = 1e-3) -> None:
        self.interval = interval
        self.stacks: collections.Counter[Stack] = collections.Counter()
        self._last = time.process_time()

    def _handler(self, signum: int, frame: FrameType | None) -> None:
        now = time.process_time()
        weight, self._last = now - self._last, now
        st: list[str] = []
        while frame is not None:
            st.append(f"{os.path.basename(frame.f_code.co_filename)}:{frame.f_code.co_name}")
            frame = frame.f_back
        self.stacks[tuple(reversed(st))] += weight

    def __enter__(self) -> Sampler:
        signal.signal(signal.SIGPROF, self._handler)
        self._last = time.process_time()
        signal.setitimer(signal.ITIMER_PROF, self.interval, self.interval)
        return self

    def __exit__(self, *exc: object) -> None:
        signal.setitimer(signal.ITIMER_PROF, 0.0, 0.0)

    def inclusive(self) -> collections.Counter[str]:
        out: collections.Counter[str] = collections.Counter()
        for st, w in self.stacks.items():
            for f in set(st):
                out[f] += w
        return out

    def own(self) -> collections.Counter[str]:
        out: collections.Counter[str] = collections.Counter()
        for st, w in self.stacks.items():
            out[st[-1]] += w
        return out

    def tree(self, root: str, depth: int, min_s: float) -> list[str]:
        """The calls under ``root`` (its outermost frame in each stack), ``depth`` levels, heaviest first."""
        sums: collections.Counter[Stack] = collections.Counter()
        for st, w in self.stacks.items():
            if root in st:
                sub = st[st.index(root):][:depth + 1]
                for j in range(1, len(sub) + 1):
                    sums[sub[:j]] += w
        lines: list[str] = []

        def walk(prefix: Stack) -> None:
            kids = [p for p in sums if len(p) == len(prefix) + 1 and p[:len(prefix)] == prefix]
            for p in sorted(kids, key=lambda p: -sums[p]):
                if sums[p] >= min_s:
                    lines.append(f"{'  ' * len(prefix)}{sums[p]:7.3f} {p[-1]}")
                    walk(p)

        if sums[(root,)]:
            lines.append(f"{sums[(root,)]:7.3f} {root}")
            walk((root,))
        return lines


def main() -> int:
    if "--" not in sys.argv:
        print(__doc__, file=sys.stderr)
        return 2
    k = sys.argv.index("--")
    ap = argparse.ArgumentParser(description="sample one graphnav CLI command's CPU")
    ap.add_argument("out", type=Path)
    ap.add_argument("--tree", metavar="FILE:FUNCTION", help="the call tree under this frame")
    ap.add_argument("--depth", type=int, default=3)
    ap.add_argument("--min", type=float, default=0.01, help="smallest entry shown [s]")
    ap.add_argument("--top", type=int, default=60)
    opts = ap.parse_args(sys.argv[1:k])
    c0 = time.process_time()
    with Sampler() as s, contextlib.redirect_stdout(io.StringIO()):
        rc = cli.main(sys.argv[k + 1:])
    cpu = time.process_time() - c0
    lines = [f"cpu {cpu:.2f} s, sampled {sum(s.stacks.values()):.2f} s", "== inclusive"]
    lines += [f"{w:7.3f} {f}" for f, w in s.inclusive().most_common(opts.top)]
    lines += ["== own"] + [f"{w:7.3f} {f}" for f, w in s.own().most_common(opts.top)]
    if opts.tree:
        lines += [f"== under {opts.tree}"] + s.tree(opts.tree, opts.depth, opts.min)
    opts.out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    print(f"cpu {cpu:.2f} s -> {opts.out}", file=sys.stderr)
    return rc


if __name__ == "__main__":
    sys.exit(main())
