"""graphnav: factor-graph navigation for unmanned surface vessels (see README.md)."""

__version__ = "0.1.0"  # = pyproject.toml's [project] version (tests/test_resume.py checks)
