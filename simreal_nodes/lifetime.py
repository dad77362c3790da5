"""A child process that ends with its parent (ROS-free): Linux ``PR_SET_PDEATHSIG``.

Used by the node processes the launcher starts (they end when the launcher does, even by ``kill -9``) and by the
tracker's registration worker (it ends with its node)."""

from __future__ import annotations

import contextlib
import os
import sys


def end_with_parent(parent: int, sig: int) -> bool:
    """Ask the kernel to send ``sig`` to this process when its parent ends (Linux; elsewhere nothing is asked and
    True is returned). False when the parent, pid ``parent``, is already gone: it died before the request, and no
    signal will come."""
    if not sys.platform.startswith("linux"):
        return True
    import ctypes

    pr_set_pdeathsig = 1
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(pr_set_pdeathsig, int(sig), 0, 0, 0)
    return os.getppid() == parent
