"""Benchmarks behind ``pfp bench NAME``: one module per benchmark.

A benchmark module is imported when ``pfp`` builds its parser, so keep its
top-level imports light and do the heavy ones inside ``run``.
"""
