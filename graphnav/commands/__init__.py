"""Sub-commands of the ``graphnav`` CLI, one module each (discovered by :mod:`graphnav.cli`)."""
