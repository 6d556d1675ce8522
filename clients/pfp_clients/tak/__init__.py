"""The TAK bridge: Cursor-on-Target in and out (``cot``), the bridge's state machine (``state``), both sans-I/O, and their pytak/Zenoh driver (``bridge``)."""
