"""Reading ahead in a thread (slam_lcd.io.prefetch): same items, same order, same errors, clean stops."""
import threading
import time

import pytest

from slam_lcd.errors import CorruptLogError
from slam_lcd.io.prefetch import prefetched


def test_items_come_in_order_and_all_of_them():
    assert list(prefetched(iter(range(1000)), depth=3)) == list(range(1000))
    assert list(prefetched([], depth=1)) == []


def test_an_error_arrives_where_it_happened_as_the_same_object():
    err = CorruptLogError("damaged chunk", "/x.mcap")

    def source():
        yield 1
        yield 2
        raise err

    it = prefetched(source(), depth=8)
    got = []
    with pytest.raises(CorruptLogError) as e:
        for x in it:
            got.append(x)
    assert got == [1, 2] and e.value is err
    with pytest.raises(StopIteration):  # finished for good
        next(it)


def test_close_stops_the_reader_and_closes_its_generator_in_its_own_thread():
    seen = {"closed_in": None, "made": 0}

    def source():
        try:
            for i in range(10_000):
                seen["made"] = i + 1
                yield i
        finally:
            seen["closed_in"] = threading.current_thread().name

    it = prefetched(source(), depth=4, name="test-reader")
    assert next(it) == 0
    time.sleep(0.05)  # the reader fills the queue and waits for room
    it.close()
    assert seen["closed_in"] == "test-reader"
    assert seen["made"] <= 3 * 4  # a bounded number ahead (the depth, a batch waiting, one being read)
    assert not it._thread.is_alive()
    with pytest.raises(StopIteration):
        next(it)


def test_the_consumer_leaving_by_an_exception_still_stops_the_reader():
    calls = []

    def source():
        for i in range(100):
            calls.append(i)
            yield i

    it = prefetched(source(), depth=2)
    with pytest.raises(KeyboardInterrupt):
        with it:
            for x in it:
                if x == 5:
                    raise KeyboardInterrupt
    n = len(calls)
    time.sleep(0.05)
    assert len(calls) == n <= 5 + 1 + 2 + 1  # nothing read after the stop


def test_depth_below_one_is_refused():
    with pytest.raises(ValueError):
        prefetched([1], depth=0)


def test_inline_until_started_then_ahead_in_the_thread():
    readers = []

    def source():
        for i in range(100):
            readers.append(threading.current_thread().name)
            yield i

    it = prefetched(source(), depth=8, name="test-reader", threaded=False)
    assert not it.threaded
    got = [next(it) for _ in range(10)]
    assert set(readers) == {threading.current_thread().name}  # the consumer read them
    it.start()
    it.start()  # again: no effect
    assert it.threaded
    got += list(it)
    assert got == list(range(100))
    assert set(readers[10:]) == {"test-reader"}


def test_close_of_an_inline_reader_closes_its_source():
    closed = []

    def source():
        try:
            yield from range(10)
        finally:
            closed.append(True)

    it = prefetched(source(), threaded=False)
    assert next(it) == 0
    it.close()
    assert closed == [True]
    with pytest.raises(StopIteration):
        next(it)


def test_reading_ahead_starts_only_once_loop_detection_hardly_waits_for_features(monkeypatch):
    from types import SimpleNamespace

    import slam_lcd.run.runner as runner
    from slam_lcd.runtime.stage_timer import StageTimer

    clock = {"t": 0.0}
    monkeypatch.setattr(runner.time, "perf_counter", lambda: clock["t"])
    timer = StageTimer()
    judge = runner._ReadAheadJudge(SimpleNamespace(timer=timer))
    n = runner._READ_AHEAD_AFTER

    def keyframe(waited: float, took: float = 1.0) -> bool:
        clock["t"] += took
        timer.seconds["features_wait"] += waited
        timer.calls["features_wait"] += 1
        return judge.pays()

    assert not judge.pays()  # nothing waited for yet (or no background extraction)
    assert not keyframe(5.0)  # a slow first forward (a GPU starting up) ...
    assert not any(keyframe(0.5) for _ in range(n))  # ... then the extraction is the bottleneck: half the time
    # keyframes that do not wait: the share over the last ten falls 0.5 -> 0.45 -> ... and is
    # below a tenth once a single waiting keyframe is left in the window (0.5 s of 10 s)
    assert not any(keyframe(0.0) for _ in range(n - 2))
    assert keyframe(0.0)  # the main thread is the bottleneck now
    assert not judge.pays()  # judged once per keyframe, not per message
