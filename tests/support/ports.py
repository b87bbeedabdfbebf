"""TCP ports of this machine held by the test, to see what a program does when the port it
would take is in use (:func:`taken`)."""

from __future__ import annotations

import contextlib
import socket


@contextlib.contextmanager
def taken(*ports: int):
    """Listen on each of ``ports`` of 127.0.0.1 for the ``with`` block; a port already in
    use by something else is left to it (taken all the same)."""
    held = []
    for port in ports:
        s = socket.socket()
        try:
            s.bind(("127.0.0.1", port))
            s.listen(1)
            held.append(s)
        except OSError:
            s.close()
    try:
        yield
    finally:
        for s in held:
            s.close()
