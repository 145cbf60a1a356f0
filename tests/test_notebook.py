"""examples/quickstart.ipynb runs top to bottom in a real Jupyter kernel (nbclient): it loads the
harbour log, smooths it record by record with graphnav.Navigator, plots Figures inline and compares
two estimators."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
NOTEBOOK = REPO / "examples" / "quickstart.ipynb"


def _kernel_or_skip() -> None:
    pytest.importorskip("nbclient", reason="nbclient (dev extra) is not installed")
    pytest.importorskip("ipykernel", reason="ipykernel (dev extra) is not installed")
    from jupyter_client.kernelspec import KernelSpecManager, NoSuchKernel

    try:
        KernelSpecManager().get_kernel_spec("python3")
    except NoSuchKernel:
        pytest.skip("no python3 Jupyter kernel available")
    if not (REPO / "data" / "harbour.npz").exists():
        pytest.skip("data/harbour.npz is absent")


def test_quickstart_notebook_runs(monkeypatch):
    _kernel_or_skip()
    import nbclient
    import nbformat

    # the kernel imports this checkout's graphnav, whatever is installed
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
    nb = nbformat.read(NOTEBOOK, as_version=4)
    client = nbclient.NotebookClient(nb, timeout=600, kernel_name="python3",
                                     resources={"metadata": {"path": str(NOTEBOOK.parent)}})
    client.execute()  # raises CellExecutionError on any failing cell
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    images = [o for o in outputs if "image/png" in o.get("data", {})]
    assert len(images) >= 3  # the plot functions' Figures, shown inline
    html = [o["data"]["text/html"] for o in outputs if "text/html" in o.get("data", {})]
    assert any("NavLog" in h or "harbour" in h for h in html)  # the log's _repr_html_
    text = "".join(o.get("text", "") for o in outputs if o.output_type == "stream")
    n, t_last = re.search(r"(\d+) online estimates; last at t = ([\d.]+) s", text).groups()
    assert int(n) > 100 and float(t_last) <= 180.0 + 1e-6
    smoothed = float(re.search(r"ATE RMSE: smoothed ([\d.]+) m", text).group(1))
    table = dict(re.findall(r"^(\S+)\s+ATE RMSE\s+([\d.]+) m", text, flags=re.M))
    assert set(table) >= {"ekf", "dead-reckoning"}
    assert smoothed < float(table["dead-reckoning"])  # the smoother beats dead reckoning
