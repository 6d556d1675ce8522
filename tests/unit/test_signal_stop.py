"""``SignalStop``: the first of SIGTERM or SIGINT sets the event and the exit code; handlers are put back."""

from __future__ import annotations

import signal

import pytest

from pfp_service.signals import SignalStop

pytestmark = pytest.mark.unit


@pytest.mark.parametrize(("first", "code"), [(signal.SIGTERM, 0), (signal.SIGINT, 130)])
def test_the_first_signal_sets_the_event_and_the_exit_code(first, code):
    before = {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGINT)}
    with SignalStop() as stop:
        assert stop.exit_code(7) == 7  # no signal: the command's own code
        signal.raise_signal(first)
        assert stop.event.is_set()
        other = signal.SIGINT if first is signal.SIGTERM else signal.SIGTERM
        signal.raise_signal(other)  # a second signal while closing changes nothing
        assert stop.exit_code(7) == code
    assert {sig: signal.getsignal(sig) for sig in before} == before


def test_an_event_given_is_the_one_set_and_install_again_keeps_the_first_handlers():
    import threading

    given = threading.Event()
    before = signal.getsignal(signal.SIGTERM)
    with SignalStop(given) as stop:
        stop.install()  # as after an asyncio loop closed
        signal.raise_signal(signal.SIGTERM)
    assert given.is_set() and stop.exit_code(1) == 0
    assert signal.getsignal(signal.SIGTERM) == before
