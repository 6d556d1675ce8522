"""``RetryingLink.close`` says whether its connecting thread ended, so ``pfp handheld`` never finalises under it.

A thread still inside ``zenoh.open`` when the interpreter finalises aborts the
process as it comes back ("FATAL: exception not rethrown", exit -6): seen when
SIGINT reached ``pfp handheld`` while it connected on a loaded machine.  The
command leaves with ``signals.leave_now`` when ``close`` returns False.
"""

from __future__ import annotations

import threading

import pytest
from pfp_clients.handheld_link import RetryingLink, client_config

from tests.zenoh_util import free_port

pytestmark = pytest.mark.net


def test_close_reports_a_connecting_thread_still_busy_then_one_that_ended() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"  # nobody listens: each try fails at once
    release = threading.Event()

    def slow_config():  # the connecting thread held where zenoh.open would be
        release.wait(30.0)
        return client_config([endpoint])

    link = RetryingLink(slow_config, endpoint, "close", "u1", retry_s=0.05)
    assert link.close(wait_s=0.2) is False  # still connecting: the command must not finalise under it
    release.set()
    assert link.close(wait_s=30.0) is True  # its try failed, it saw the stop and ended
    assert not link.connected


def test_close_of_a_link_that_never_connected_ends_its_thread() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    link = RetryingLink(lambda: client_config([endpoint]), endpoint, "close", "u2", retry_s=0.05)
    assert link.close(wait_s=30.0) is True
