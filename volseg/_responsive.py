"""A long computation the main thread can still be interrupted in.

Python runs a signal's handler (SIGTERM, Ctrl-C) in the main thread, between two of
its bytecodes: while the main thread is inside one long compiled call (a numba kernel
over a 512^3 volume runs for seconds) the handler waits for it. `responsive` runs the
call in a worker thread and keeps the main thread waiting in short joins, so the
handler runs at once: its KeyboardInterrupt unwinds the caller's with-blocks
(staging removed, lock released) while the worker is still busy; the command then
exits (`volseg.cli`), which ends the worker. The compiled kernels release the GIL
(numba's parallel kernels and ``nogil`` ones), so the main thread gets it.
"""

from __future__ import annotations

import threading

__all__ = ["responsive"]

#: How often the waiting main thread wakes, in seconds.
POLL = 0.05


def responsive(function, *args, **kwargs):
    """``function(*args, **kwargs)``, run in a worker thread when called from the main
    thread (as it is, elsewhere); its result or its exception. An interrupt of the
    main thread leaves the worker running to its end (a daemon thread: the process's
    exit ends it); nothing it returns after that is used."""
    if threading.current_thread() is not threading.main_thread():
        return function(*args, **kwargs)
    box = {}

    def run():
        try:
            box["value"] = function(*args, **kwargs)
        except BaseException as err:       # handed to the caller, whatever it is
            box["error"] = err

    worker = threading.Thread(target=run, name="volseg-compute", daemon=True)
    worker.start()
    while worker.is_alive():
        worker.join(POLL)
    if "error" in box:
        raise box["error"]
    return box["value"]
