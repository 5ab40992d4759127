"""Work split with a helper process (util.helper.Split): the same results as one process, state kept
between steps on the side that holds each item, the helper's exceptions raised here, and the work
finished here when the helper dies or cannot start."""
from __future__ import annotations

import os
import signal

import numpy as np
import pytest

import imu_learn.util.helper as helper
from imu_learn.util.helper import Split


def accumulate(item, state, k):
    """A step with state: the item's running sum of k * item, and where it ran."""
    state["sum"] = state.get("sum", 0.0) + k * float(np.sum(item))
    return state["sum"], os.getpid()


def fail_on_odd(item, state):
    if int(item[0]) % 2:
        raise ValueError(f"item {int(item[0])} is odd")
    return int(item[0])


ITEMS = [np.full(1000, i, dtype=np.float64) for i in range(5)]


def sums(split: Split) -> list:
    first = split.step(accumulate, 1.0)
    second = split.step(accumulate, 2.0)
    return [v for v, _ in first] + [v for v, _ in second]


def expected() -> list:
    return [1000.0 * i for i in range(5)] + [3000.0 * i for i in range(5)]


def test_the_helper_runs_every_other_item_with_its_state_and_the_same_results():
    with Split(ITEMS, helper=True) as split:
        assert split.theirs == [1, 3]
        first = split.step(accumulate, 1.0)
        second = split.step(accumulate, 2.0)
    pids = [pid for _, pid in first]
    assert [pids[i] == os.getpid() for i in range(5)] == [True, False, True, False, True]
    assert [pid for _, pid in second] == pids  # each item stays where its state is
    assert [v for v, _ in first] + [v for v, _ in second] == expected()
    with Split(ITEMS, helper=False) as alone:
        assert alone.theirs == [] and sums(alone) == expected()


def test_an_exception_in_the_helper_is_raised_here_as_itself():
    with Split([np.array([0.0]), np.array([1.0])], helper=True) as split:
        assert split.theirs == [1]
        with pytest.raises(ValueError, match="item 1 is odd"):
            split.step(fail_on_odd)


def test_a_helper_that_dies_between_steps_leaves_its_items_to_this_process():
    with Split(ITEMS, helper=True) as split:
        first = split.step(accumulate, 1.0)
        os.kill(split._helper.proc.pid, signal.SIGKILL)
        split._helper.proc.wait()
        second = split.step(accumulate, 2.0)  # the lost items' first step replayed here
        assert split.theirs == []
    assert [v for v, _ in first] + [v for v, _ in second] == expected()
    assert all(pid == os.getpid() for _, pid in second)


def test_a_helper_that_cannot_start_leaves_every_item_here(monkeypatch):
    def broken(*a, **k):
        raise OSError("no processes here")

    monkeypatch.setattr(helper.subprocess, "Popen", broken)
    with Split(ITEMS, helper=True) as split:
        assert split.theirs == []
        assert sums(split) == expected()


def test_closing_ends_the_helper():
    split = Split(ITEMS, helper=True)
    proc = split._helper.proc
    split.step(accumulate, 1.0)
    split.close()
    assert proc.poll() is not None


def test_a_helper_that_cannot_load_a_step_leaves_its_items_here_quietly(monkeypatch, capfd):
    """The helper's sys.path without this test module: it cannot unpickle the step's function."""
    monkeypatch.setattr(helper.sys, "path", ["/nonexistent"])
    with Split(ITEMS, helper=True) as split:
        assert sums(split) == expected()
        assert split.theirs == []
    assert "Traceback" not in capfd.readouterr().err


def fail_here(item, state):
    """Fails on the items this process runs (item 0), succeeds in the helper."""
    if os.getpid() == int(item[1]):
        raise RuntimeError("failed here")
    return float(item[0])


def test_splits_in_a_shared_block_reuse_one_helper_and_start_clean():
    with helper.shared_helper(("test_helper_process",)):
        with Split(ITEMS) as first:  # no start=True: the shared helper
            a = first.step(accumulate, 1.0)
        with Split(ITEMS) as second:
            b = second.step(accumulate, 1.0)  # a fresh state: not the first Split's sums
        assert [v for v, _ in a] == [v for v, _ in b] == expected()[:5]
        assert a[1][1] == b[1][1] != os.getpid()  # the same helper process
    assert not helper._shared
    with Split(ITEMS) as alone:  # outside the block, without start=True: no helper
        assert alone.theirs == []


def test_a_split_left_with_a_reply_unread_does_not_hand_it_to_the_next():
    items = [np.array([0.0, os.getpid()]), np.array([1.0, os.getpid()])]
    with helper.shared_helper():
        with pytest.raises(RuntimeError, match="failed here"):
            with Split(items) as split:
                pid = split._helper.proc.pid
                split.step(fail_here)  # raised here while the helper's reply was on its way
        with Split(ITEMS) as after:
            assert [v for v, _ in after.step(accumulate, 1.0)] == expected()[:5]
            assert after._helper is None or after._helper.proc.pid != pid


def test_a_start_up_that_prints_is_not_read_as_a_reply(tmp_path, monkeypatch, capfd):
    """A site customisation that prints a banner when any interpreter starts (text that begins like a
    pickle opcode: 'B' announces a huge read) went into the replies and hung the command."""
    (tmp_path / "sitecustomize.py").write_text('print("Boot environment: lab-A")\n')
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))
    signal.signal(signal.SIGALRM, lambda *a: (_ for _ in ()).throw(TimeoutError("the split hung")))
    signal.alarm(60)
    try:
        with Split(ITEMS, helper=True) as split:
            out = split.step(accumulate, 1.0)
            assert split.theirs == [1, 3]  # the helper kept its items: nothing went wrong
    finally:
        signal.alarm(0)
    assert [v for v, _ in out] == expected()[:5]
    assert out[1][1] != os.getpid()
    assert "Boot environment" in capfd.readouterr().err  # the banner shows, on stderr
