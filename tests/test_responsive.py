"""An interrupt is not kept waiting by a long compiled call (issue 57, #7): the
command's in-memory stages run in a worker thread, the main thread stays free for a
signal's handler."""

import signal
import subprocess
import sys
import textwrap
import time

import pytest

from volseg._responsive import responsive

#: A child process: a nogil numba kernel that would spin for minutes, called directly
#: or through `responsive`, a SIGTERM handler raising KeyboardInterrupt as the CLI's.
CHILD = textwrap.dedent("""
    import os, signal, sys
    import numba
    from volseg._responsive import responsive

    @numba.njit(nogil=True)
    def spin(n):
        s = 0
        for i in range(n):
            s = (s + i * i) % 7919
        return s

    spin(10)                                   # compiled before the parent's clock
    def interrupted(signum, frame):
        raise KeyboardInterrupt
    signal.signal(signal.SIGTERM, interrupted)
    print("started", flush=True)
    try:
        (responsive if sys.argv[1] == "responsive" else lambda f, *a: f(*a))(spin, 10**13)
    except KeyboardInterrupt:
        print("interrupted", flush=True)
        os._exit(130)
""")


def _seconds_to_exit(how):
    child = subprocess.Popen([sys.executable, "-c", CHILD, how], stdout=subprocess.PIPE,
                             text=True)
    assert child.stdout.readline().strip() == "started"
    time.sleep(0.3)
    started = time.perf_counter()
    child.send_signal(signal.SIGTERM)
    try:
        child.wait(timeout=5)
    except subprocess.TimeoutExpired:
        child.kill()
        child.wait()
        return None, ""
    return time.perf_counter() - started, child.stdout.read()


def test_a_sigterm_ends_a_long_kernel_at_once_through_responsive():
    seconds, out = _seconds_to_exit("responsive")
    assert seconds is not None and seconds < 1.0 and "interrupted" in out
    # The same kernel called on the main thread keeps the handler waiting.
    seconds, _ = _seconds_to_exit("direct")
    assert seconds is None


def test_responsive_gives_the_result_or_the_error():
    assert responsive(sum, [1, 2, 3]) == 6
    with pytest.raises(ZeroDivisionError):
        responsive(lambda: 1 / 0)
