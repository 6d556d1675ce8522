"""The TAK bridge: Cursor-on-Target in and out (``cot``, sans-I/O) and its Zenoh/pytak driver (``bridge``)."""
