"""The live world: the sans-I/O state machine of one mission (``world.World``) and its parts.

Values in, values out: ``World.apply(inputs, now)`` and ``World.next_deadline()``. Nothing here
reads a clock, a socket, a file or a thread; import-linter holds it to that (pyproject.toml).
"""
