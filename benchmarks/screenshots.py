"""Screenshots of the report, for docs/img/: the demo (a log with truth) and a real NMEA log without
truth (psaros33, 10 minutes under way, with a GNSS hold-out), each opened in headless Chromium as
tests/evaluation/test_report.py opens it.

    python benchmarks/screenshots.py                 # runs both reports, writes docs/img/report-*.png
    python benchmarks/screenshots.py --demo-dir D    # reuse a demo's output directory (report.html)

Needs Debian's ``chromium`` (``apt-get install chromium``) and, for the NMEA log,
../shared/data/marine/anemomind/psaros33-20140627-0006.nmea.gz.
"""

from __future__ import annotations

import argparse
import gzip
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
IMG = REPO / "docs" / "img"
PSAROS = REPO.parent / "shared" / "data" / "marine" / "anemomind" / "psaros33-20140627-0006.nmea.gz"
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run", "--hide-scrollbars"]
#: lines of the psaros33 log under way (10 minutes; RMC/GLL/HDG/VHW), as in tests/evaluation/test_holdout.py
SLICE = (43608, 49000)


def graphnav(*argv: str) -> None:
    r = subprocess.run([sys.executable, "-m", "graphnav", *argv], cwd=REPO, capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"graphnav {' '.join(argv)}: exit {r.returncode}\n{r.stderr[-2000:]}")


def shoot(html: Path, png: Path, size: str = "1400,2600") -> None:
    """``html`` opened in headless Chromium, its top ``size`` pixels saved to ``png``."""
    chromium = shutil.which("chromium")
    if chromium is None:
        raise SystemExit("chromium is not installed (apt-get install chromium)")
    with tempfile.TemporaryDirectory() as profile:
        r = subprocess.run([chromium, *FLAGS, f"--user-data-dir={profile}", f"--window-size={size}",
                            f"--screenshot={png}", html.resolve().as_uri()], capture_output=True, text=True,
                           timeout=300)
    if r.returncode != 0 or not png.exists():
        raise SystemExit(f"chromium failed on {html}: {r.stderr[-2000:]}")
    print(f"wrote {png.relative_to(REPO)}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--demo-dir", type=Path, help="an existing `graphnav demo --out DIR` (default: run it)")
    ap.add_argument("--nmea-dir", type=Path, help="an existing report of the NMEA slice (default: run it)")
    args = ap.parse_args(argv)
    IMG.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        demo = args.demo_dir
        if demo is None:
            demo = Path(tmp) / "demo"
            graphnav("demo", "--out", str(demo))
        shoot(demo / "report.html", IMG / "report-demo.png")
        nmea = args.nmea_dir
        if nmea is None:
            if not PSAROS.exists():
                raise SystemExit(f"the anemomind log is not at {PSAROS}")
            log = Path(tmp) / "psaros33-slice.nmea"
            with gzip.open(PSAROS, "rt", encoding="ascii", errors="replace") as fh:
                log.write_text("".join(fh.readlines()[SLICE[0]:SLICE[1]]))
            nmea = Path(tmp) / "nmea"
            graphnav("compare", str(log), "--holdout-gnss", "200,40", "--out", str(nmea))
        shoot(nmea / "report.html", IMG / "report-nmea-no-truth.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
