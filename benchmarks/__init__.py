"""Benchmarks behind ``pfp bench NAME``: one module per benchmark, outside the shipped package.

``pfp bench`` loads this package from beside ``pfp_service`` in a source checkout
(``pfp_service.cli.bench``); a wheel ships neither it nor its tests' fixtures.  It
may import ``pfp_service`` and ``pfp_clients``; nothing there imports it.  A
module whose name starts with ``_`` is a helper and is never imported to build
the parser; ``recorder`` is a program of its own (``python -m benchmarks.recorder``).

A benchmark module is imported when ``pfp`` builds its parser, so keep its
top-level imports light and do the heavy ones inside ``run``.
"""
