"""Pool workers that end with the process that started them.

A process pool's workers outlive a parent that is killed outright (SIGKILL, or SIGTERM sent to
the parent alone, as `kill PID` or a batch scheduler does): they go on with the trials already
queued to them and hold the CPUs for an hour. On Linux a worker asks the kernel for SIGTERM
when its parent ends (``prctl(PR_SET_PDEATHSIG)``); elsewhere nothing changes.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys

PR_SET_PDEATHSIG = 1
"""prctl option: the signal this process gets when its parent (the thread that started it)
ends."""


def end_with_parent(parent: int) -> None:
    """In a worker, first thing: SIGTERM when ``parent`` (its pid) ends; if it already has,
    now."""
    if not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
    except (OSError, AttributeError):  # no libc prctl here: the worker lives as before
        return
    if os.getppid() != parent:  # the parent ended before the request was made
        os.kill(os.getpid(), signal.SIGTERM)
