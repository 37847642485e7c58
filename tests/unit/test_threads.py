"""Background threads lower their own priority (Linux: per thread), the caller's stays."""

import os
import sys
import threading
from concurrent.futures import ThreadPoolExecutor

import pytest

from drivers import threads


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="per-thread nice is Linux's")
def test_a_background_thread_runs_below_the_event_loops_thread():
    main = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    with ThreadPoolExecutor(1, initializer=threads.lower_this_thread) as pool:
        worker = pool.submit(lambda: os.getpriority(os.PRIO_PROCESS,
                                                    threading.get_native_id())).result()
    assert worker == min(19, main + 10)
    assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) == main


def test_zero_leaves_background_threads_as_they_are():
    threads.set_background_nice(0)
    try:
        with ThreadPoolExecutor(1, initializer=threads.lower_this_thread) as pool:
            worker = pool.submit(lambda: os.getpriority(os.PRIO_PROCESS,
                                                        threading.get_native_id())).result()
        assert worker == os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    finally:
        threads.set_background_nice(10)
