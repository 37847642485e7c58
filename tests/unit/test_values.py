"""The ``name::value`` board: anything publishes, the console shows the newest of each."""

from __future__ import annotations

import math
import threading

import numpy as np

from autopilot import values
from autopilot.values import MAX_VALUES, ValueBoard


def test_newest_value_of_each_name_with_units():
    board = ValueBoard()
    board.publish("tgt.x", 10)
    board.publish("tgt.x", 12, "px")
    board.publish("ok", True)
    board.publish("range_m", np.float64(2.5), "m")
    board.publish("bad", math.nan)
    board.publish("thing", object())
    snap = board.snapshot()
    assert snap["tgt.x"].value == 12
    assert snap["tgt.x"].unit == "px"
    assert snap["ok"].value is True
    assert snap["range_m"].value == 2.5
    assert isinstance(snap["range_m"].value, float)
    assert snap["bad"].value == "nan"  # shown, never an invalid JSON number
    assert isinstance(snap["thing"].value, str)
    board.remove("tgt.")
    assert "tgt.x" not in board.snapshot()


def test_a_runaway_publisher_cannot_grow_the_board_without_bound():
    board = ValueBoard()
    for i in range(MAX_VALUES + 50):
        board.publish(f"v{i}", i)
    assert len(board.snapshot()) == MAX_VALUES
    assert board.refused == 50


def test_publishing_from_threads_and_the_process_board():
    board = ValueBoard()

    def work(k):
        for i in range(500):
            board.publish(f"t{k}", i)

    threads = [threading.Thread(target=work, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert {board.snapshot()[f"t{k}"].value for k in range(4)} == {499}
    values.board().clear()
    values.publish("x", 1)
    assert values.board().snapshot()["x"].value == 1
