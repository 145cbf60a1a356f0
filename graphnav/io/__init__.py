"""Readers and writers of navigation logs. :func:`graphnav.io.load_log` picks one by path."""

from .dispatch import load_log, save_log

__all__ = ["load_log", "save_log"]
