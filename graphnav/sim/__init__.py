"""Simulators: each module is one scenario (``harbour``, ``fairway``, ``solent``, ``marina-degraded``).
The numeric cores take a seed and return a :class:`graphnav.log.NavLog`; they write no files. The
``graphnav simulate`` command (:mod:`graphnav.commands.simulate`) holds their command-line glue."""
