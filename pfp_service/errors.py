"""The project's exceptions, and the translation of decoder errors at the boundary.

    PfpError                    anything this package raises on purpose
    └── InputError              bad input from outside: a file, a flag, a wire message
        └── (path, reason)      e.g. ``threats[2].sigma_range: must be > 0``

Planning failure is *not* an exception: a plan's ``status`` says it.  A CLI
turns an ``InputError`` into one line on stderr and exit code 2; the daemon
turns it into a structured rejection and carries on.
"""

from __future__ import annotations

import re

import msgspec

__all__ = ["InputError", "PfpError", "from_validation"]


class PfpError(Exception):
    """Base of every exception this package raises on purpose."""


class InputError(PfpError):
    """Input that cannot be used, with the field path (``""`` for the whole) and why."""

    def __init__(self, path: str, reason: str) -> None:
        super().__init__(f"{path}: {reason}" if path else reason)
        self.path = path
        self.reason = reason


# Bounds used as "finite" sentinels by ``pfp_service.constraints``; NaN fails them too.
FINITE_LIMIT = 1e9

_AT = re.compile(r"^(?P<msg>.*) - at `\$(?P<path>[^`]*)`$", re.S)
_BOUND = re.compile(r"^Expected `(?P<type>\w+)` (?P<op>[<>]=?) (?P<num>[-\d.e+]+)$")
_LEN = re.compile(r"^Expected `(?P<type>\w+)` of length (?P<op>[<>]=?) (?P<num>\d+)$")
_MISSING = re.compile(r"^Object missing required field `(?P<field>[^`]+)`$")
_UNKNOWN = re.compile(r"^Object contains unknown field `(?P<field>[^`]+)`$")
_OWN = re.compile(r"^(?P<field>[A-Za-z_][\w\[\].]*): (?P<reason>.+)$", re.S)


def _join(path: str, field: str) -> str:
    if not path:
        return field
    return f"{path}{field}" if field.startswith("[") else f"{path}.{field}"


def _num(text: str) -> str:
    value = float(text)
    return f"{value:g}"


def from_validation(
    exc: msgspec.ValidationError | msgspec.DecodeError, choices: dict[str, tuple[str, ...]] | None = None
) -> InputError:
    """Turn a msgspec error into ``InputError(path, reason)`` in this project's words.

    Args:
        exc: the decoder's error.
        choices: allowed values of enum-like fields by field name, named in the reason.
    """
    text = str(exc)
    m = _AT.match(text)
    msg, path = (m["msg"], m["path"].lstrip(".")) if m else (text, "")
    if (b := _BOUND.match(msg)) is not None:
        bound = float(b["num"])
        if abs(bound) == FINITE_LIMIT:
            return InputError(path, f"expected a finite number within ±{FINITE_LIMIT:g}")
        return InputError(path, f"must be {b['op']} {_num(b['num'])}")
    if (b := _LEN.match(msg)) is not None:
        return InputError(path, f"length must be {b['op']} {b['num']}")
    if (b := _MISSING.match(msg)) is not None:
        return InputError(_join(path, b["field"]), "is required")
    if (b := _UNKNOWN.match(msg)) is not None:
        return InputError(_join(path, b["field"]), "unknown field")
    if msg.startswith("Invalid enum value"):
        name = re.split(r"[.\[]", path)[-1] if path else ""
        allowed = (choices or {}).get(name)
        extra = f" (expected one of: {', '.join(allowed)})" if allowed else ""
        return InputError(path, msg.replace("Invalid enum value", "unknown value") + extra)
    if msg.startswith("Expected `"):
        return InputError(path, "expected " + msg[len("Expected ") :].replace("`", ""))
    if not isinstance(exc, msgspec.ValidationError):
        return InputError(path, "malformed JSON: " + msg.split(": ", 1)[-1])
    if (b := _OWN.match(msg)) is not None:
        return InputError(_join(path, b["field"]), b["reason"])
    return InputError(path, msg[0].lower() + msg[1:] if msg else "invalid")
