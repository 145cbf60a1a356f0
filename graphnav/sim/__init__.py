"""Simulators: each module is one scenario (``harbour``, ``fairway``, ``solent``, ``marina-degraded``)
and registers itself under ``graphnav simulate``. The numeric cores take a seed and return a
:class:`graphnav.log.NavLog`; only ``register``/the CLI glue writes files."""
