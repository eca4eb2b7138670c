"""One pass over a log serves both the run and corrected.mcap's copy: the undecoded
messages handed to a raw sink are exactly what ``raw_messages`` reads, the decoded stream is
unchanged, and a RawSpool gives them back as they came."""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.io import open_log
from slam_lcd.io.log_backend import RawMessage
from slam_lcd.io.raw_spool import RawSpool


def _raw(msgs) -> list[tuple]:
    return [(m.topic, m.msgtype, m.log_time, bytes(m.data)) for m in msgs]


@pytest.mark.parametrize("name", ["ROS_example.bag", "tf_example", "nav2_turtlebot.mcap"])
def test_raw_sink_gets_what_raw_messages_reads_and_the_decoded_stream_is_unchanged(shared_data, name):
    path = shared_data / "bags" / name
    with open_log(path) as r:
        topics = sorted(r.topics, key=lambda t: -r.topics[t].count)
        wanted, raw_only = topics[:1], topics[1:3]
        raw_topics = raw_only + wanted  # one topic both decoded and copied, others copied only
        plain = [(m.topic, m.stamp, m.log_time) for m in r.messages(wanted)]
        reference = _raw(r.raw_messages(raw_topics))
        got: list[RawMessage] = []
        both = [(m.topic, m.stamp, m.log_time) for m in r.messages(wanted, raw_topics=raw_topics,
                                                                    raw_sink=lambda m: got.append(
                                                                        RawMessage(m.topic, m.msgtype, m.log_time,
                                                                                   bytes(m.data))))]
    assert both == plain and len(plain) > 0
    assert sorted(_raw(got)) == sorted(reference) and len(reference) > len(plain)
    assert [m.log_time for m in got] == sorted(m.log_time for m in got)  # log-time order, as the pass reads


def test_spool_gives_back_its_records_in_order_and_is_removed(tmp_path):
    rng = np.random.default_rng(0)
    msgs = [RawMessage(f"/t{i % 3}", "std_msgs/msg/String", 1000 + i, rng.bytes(int(rng.integers(0, 300))))
            for i in range(500)]
    spool = RawSpool(tmp_path / "staging" / ".spool", ["/t0", "/t1", "/t2"])
    for m in msgs:
        spool.add(m)
    with pytest.raises(RuntimeError, match="finish"):
        next(iter(spool))
    spool.finish(complete=True)
    assert spool.complete and spool.count == 500 and spool.topics() == ["/t0", "/t1", "/t2"]
    assert list(spool) == msgs and list(spool) == msgs  # read back twice, the same
    with open(spool.path, "r+b") as fh:  # a damaged spool is an error, not a short copy
        fh.truncate(spool.path.stat().st_size - 5)
    with pytest.raises(OSError, match="inside a record"):
        list(spool)
    spool.discard()
    assert not spool.path.exists()


def test_corrected_mcap_from_the_spool_equals_the_copy_read_from_the_log(report_run, tmp_path):
    """write_corrected_log with the run's spool writes the same file content as reading the log again;
    an incomplete spool (an interrupted pass) is not used."""
    from mcap.reader import make_reader

    from slam_lcd.config import load_config
    from slam_lcd.io.trajectory_files import read_tum
    from slam_lcd.outputs.corrected_log import copied_topics, write_corrected_log
    from slam_lcd.sensors.topics import copyable_topics

    _, out, log = report_run
    odom, corr, kf = (read_tum(out / n) for n in ("odometry.tum", "corrected.tum", "keyframes_corrected.tum"))
    cfg = load_config("default")
    with open_log(log) as r:
        copy = copyable_topics(r, False, log)
        spool = RawSpool(tmp_path / "spool", copied_topics(copy))
        n = sum(1 for _ in r.messages(["/camera/image_raw"], raw_topics=spool.wanted, raw_sink=spool.add))
    assert n > 0 and spool.count > 0
    frames = {"odom": "odom", "body": "base_link", "gt": "world"}

    def write(name, spooled):
        write_corrected_log(tmp_path / name, odom=odom, corrected=corr, kf_ids=list(range(len(kf))),
                            kf_corrected=kf, loops=[], log_frame_ids=frames, run_conf=cfg.run, copy_from=log,
                            copy_topics=copy, spooled=spooled)
        with open(tmp_path / name, "rb") as fh:
            return [(c.topic, m.log_time, bytes(m.data))
                    for _, c, m in make_reader(fh).iter_messages(log_time_order=True)]

    spool.finish(complete=True)
    from_log, from_spool = write("log.mcap", None), write("spool.mcap", spool)
    assert from_spool == from_log and len(from_log) > spool.count
    spool.discard()  # an interrupted pass: the spool is gone, the log is read instead
    spool.complete = False
    assert write("partial.mcap", spool) == from_log
