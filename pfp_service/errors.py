"""The project's exceptions, and the translation of third-party errors at the boundary.

    PfpError                    anything this package raises on purpose
    ├── DeadlinePassed          a computation's deadline passed inside it (a preview's
    │                           metrics, say): its answer is "expired", never a partial one
    └── InputError              bad input from outside: a file, a flag, a wire message
        │                       (path, reason), e.g. ``threats[2].sigma_range: must be > 0``
        └── ZenohError          Zenoh refused a flag or setting: a malformed endpoint,
            │                   a port in use, a Zenoh JSON5 file it cannot read
            └── Unreachable     no router or peer answered at the endpoints given

Planning failure is *not* an exception: a plan's ``status`` says it.  A CLI
turns an ``InputError`` into one line on stderr and exit code 2; the daemon
turns it into a structured rejection and carries on.  ``from_validation``
translates msgspec's errors and ``map_zenoh_errors()`` Zenoh's (one human
line, no Rust source paths), each with ``raise ... from exc``.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from contextlib import contextmanager

import msgspec

__all__ = [
    "DeadlinePassed",
    "InputError",
    "PfpError",
    "Unreachable",
    "ZenohError",
    "describe_zenoh_error",
    "from_validation",
    "map_zenoh_errors",
]


class PfpError(Exception):
    """Base of every exception this package raises on purpose."""


class DeadlinePassed(PfpError):
    """A computation checked its deadline where it spends its time, and the deadline had passed."""


class InputError(PfpError):
    """Input that cannot be used, with the field path (``""`` for the whole) and why."""

    def __init__(self, path: str, reason: str) -> None:
        super().__init__(f"{path}: {reason}" if path else reason)
        self.path = path
        self.reason = reason


class ZenohError(InputError):
    """Zenoh refused what it was given (``path`` names the flag or setting)."""


class Unreachable(ZenohError):
    """No router or peer answered at the endpoints given."""


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


# -- Zenoh's errors ------------------------------------------------------------------------
# zenoh.ZError texts carry Rust source locations and debug-printed wrappers, e.g.
#   Json5Err(Message { msg: "Endpoints must be of the form ...: x at /root/.cargo/.../endpoint.rs:615.", ... })
_RUST_AT = re.compile(r"\s*\bat /\S+?\.rs:\d+\.?")
_JSON5 = re.compile(r'Json5Err\(Message \{ msg: "(?P<msg>(?:[^"\\]|\\.)*)"')
_ENDPOINT_FORM = re.compile(r"Endpoints must be of the form [^:]*: (?P<text>.*)$")
_IN_USE = re.compile(r"bound to (?P<ep>\S+?): .*Address already in use", re.S)
_UNREACHABLE = re.compile(r"Unable to connect to any of \[(?P<eps>.*)\]")
_PARSE = re.compile(r"-->\s*(?P<line>\d+):(?P<col>\d+).*=\s*(?P<what>[^\n]*)$", re.S)
_OS_ERROR = re.compile(r"\s*\(os error \d+\)")


def _is_zenoh(exc: BaseException) -> bool:
    # matched by module so this file (imported by the sans-I/O core) never imports zenoh
    return type(exc).__module__.split(".")[0] == "zenoh"


def describe_zenoh_error(text: str) -> tuple[str, bool]:
    """Zenoh's error text as one human line, and whether it says nothing answered.

    Returns:
        ``(line, unreachable)``: the line has no source paths, no debug wrappers and no newlines.
    """
    text = _RUST_AT.sub("", str(text))
    if (m := _JSON5.search(text)) is not None:
        text = m["msg"].replace('\\"', '"')
        text = _RUST_AT.sub("", text)
    if (m := _ENDPOINT_FORM.search(text)) is not None:
        return (
            f"{m['text'].strip()!r} is not an endpoint (expected PROTOCOL/ADDRESS, e.g. tcp/10.0.0.1:7447)",
            False,
        )
    if (m := _IN_USE.search(text)) is not None:
        return f"cannot listen on {m['ep']}: address already in use", False
    if (m := _UNREACHABLE.search(text)) is not None:
        eps = re.sub(r"Single\((.*?)\)", r"\1", m["eps"])
        return f"no router answers at {eps}", True
    if (m := _PARSE.search(text)) is not None:
        return f"invalid JSON5 at line {m['line']} column {m['col']}: {m['what'].strip()}", False
    text = _OS_ERROR.sub("", text)
    text = " ".join(text.replace("[", " ").replace("]", " ").split())
    return (text[0].lower() + text[1:] if text else "zenoh refused it"), False


@contextmanager
def map_zenoh_errors(what: str, about: str = "") -> Iterator[None]:
    """Translate a Zenoh error raised inside the block into a ``ZenohError`` naming ``what``.

    Args:
        what: the flag or setting the Zenoh call was given (``--connect``, ``--listen``, ``zenoh_config``).
        about: put before the reason, e.g. the file the setting names.

    Raises:
        Unreachable: no router answered; ZenohError: anything else Zenoh refused.
    """
    try:
        yield
    except Exception as exc:
        if not _is_zenoh(exc):
            raise
        line, unreachable = describe_zenoh_error(str(exc))
        raise (Unreachable if unreachable else ZenohError)(
            what, f"{about}: {line}" if about else line
        ) from exc
