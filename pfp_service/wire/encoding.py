"""The one Zenoh-specific choice of the wire: the encoding every payload is put and replied with.

A module of its own, so that importing ``pfp_service.wire`` never reaches zenoh, not even
through a function: the sans-I/O world imports the wire's messages and keys, and
``make check`` (import-linter) holds that nothing it imports leads to zenoh.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import zenoh

__all__ = ["zenoh_encoding"]


def zenoh_encoding() -> zenoh.Encoding:
    """The Zenoh encoding every payload is put and replied with: ``APPLICATION_JSON``.

    Predefined encodings travel as a small integer; ``str()`` of it is ``CONTENT_TYPE``.
    """
    import zenoh  # when called: importing the module stays as light as the rest of the wire

    return zenoh.Encoding.APPLICATION_JSON
