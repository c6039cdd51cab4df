"""SetMatcher: when a set is final, what it reports missing, and what it never does (fill a set
from another trigger). Driven with explicit arrival times, so every rule is checked exactly."""
from __future__ import annotations

from stereocam.frame_sets import SetMatcher
from stereocam.frames import DisparityFormat, Frame, StereoGeometry

NAMES = ("A", "B", "C")


def frame(tid: int, host_time: float = 0.0) -> Frame:
    return Frame(tid, tid, tid * 1000, host_time, None, None, None, 0, 0, 160, 120, False,
                 DisparityFormat(16, 0, 64, -16), StereoGeometry(0.0, 0.0, 0.0, 0.0))


def test_a_set_goes_as_soon_as_every_camera_delivered_or_moved_past_it():
    m = SetMatcher(NAMES, deadline=1.0)
    for n in NAMES:
        m.add(n, frame(1), now=0.0)
    assert [(s.trigger_id, s.missing) for s in m.pop_ready(0.0)] == [(1, ())]
    m.add("A", frame(2), 0.1)
    m.add("B", frame(2), 0.1)
    assert m.pop_ready(0.2) == []  # C may still deliver 2
    m.add("C", frame(3), 0.2)  # C moved past 2: its frame for 2 will never come
    (s,) = m.pop_ready(0.2)
    assert (s.trigger_id, s.missing, set(s.frames)) == (2, ("C",), {"A", "B"})
    assert m.stats.missing == {"C": 1} and m.stats.complete == 1 and m.stats.incomplete == 1


def test_a_silent_camera_is_reported_after_the_deadline_not_before():
    m = SetMatcher(NAMES, deadline=0.5)
    for n in NAMES:
        m.add(n, frame(1), 0.0)
    m.pop_ready(0.0)
    m.add("A", frame(2), 1.0)
    m.add("B", frame(2), 1.0)
    assert m.pop_ready(1.4) == []
    (s,) = m.pop_ready(1.6)
    assert s.missing == ("C",)
    m.add("C", frame(2), 1.7)  # too late: counted, never put in another set
    m.add("A", frame(3), 1.7)
    m.add("B", frame(3), 1.7)
    m.add("C", frame(3), 1.7)
    (s3,) = m.pop_ready(1.7)
    assert s3.complete and all(f.trigger_id == 3 for f in s3.frames.values()) and m.stats.late == {"C": 1}


def test_a_pulse_no_camera_captured_is_a_set_missing_all():
    m = SetMatcher(NAMES, deadline=0.5)
    for tid in (5, 6, 8):
        for n in NAMES:
            m.add(n, frame(tid), 0.0)
    assert [(s.trigger_id, len(s.missing)) for s in m.pop_ready(0.0)] == [(5, 0), (6, 0), (7, 3), (8, 0)]


def test_sets_begin_when_every_camera_streams():
    m = SetMatcher(NAMES, deadline=0.5)
    m.add("A", frame(1), 0.0)  # A started first; B and C from trigger 2 on
    m.add("A", frame(2), 0.03)
    m.add("B", frame(2), 0.03)
    m.add("C", frame(2), 0.03)
    assert [(s.trigger_id, s.complete) for s in m.pop_ready(0.03)] == [(2, True)]
    assert m.stats.before_start == 1


def _bounded_run(m: SetMatcher, liar: str, jump: int) -> tuple[list, float]:
    """Ten honest pulses, the liar's frame for pulse 5 claiming ``5 + jump``."""
    import time
    out, t0 = [], time.perf_counter()
    for tid in range(1, 11):
        for n in NAMES:
            m.add(n, frame(tid + jump if (n == liar and tid == 5) else tid), tid * 0.01)
        out += m.pop_ready(tid * 0.01)
    out += m.pop_ready(10.0)
    return out, time.perf_counter() - t0


def test_a_head_lying_about_trigger_ids_costs_bounded_work_and_is_named():
    for jump in (10**6, 10**7, 2**32, 2**63):
        m = SetMatcher(NAMES, deadline=0.5)
        sets, took = _bounded_run(m, "B", jump)
        assert took < 0.5 and len(sets) <= 10, (jump, took, len(sets))
        assert [s.trigger_id for s in sets] == list(range(1, 11))
        assert [s.trigger_id for s in sets if not s.complete] == [5] and sets[4].missing == ("B",)
        assert m.stats.implausible == {"B": 1}


def test_a_jump_every_camera_makes_is_followed_and_the_gap_counted_not_filled():
    m = SetMatcher(("A", "B"), deadline=0.5)
    for tid in (1, 2, 10**7, 10**7 + 1):
        for n in ("A", "B"):
            m.add(n, frame(tid), 0.0)
    sets = m.pop_ready(0.0)
    assert [(s.trigger_id, s.missing) for s in sets] == [(1, ()), (2, ()), (10**7, ("A",)), (10**7 + 1, ())]
    assert m.stats.implausible == {"A": 1} and m.stats.skipped == 10**7 - 3


def test_a_liar_whose_frame_comes_first_does_not_set_the_start():
    """A lying head's frame is the very first one the matcher sees: nothing could refuse it then, so
    the start (the first trigger every camera streamed for) ignores it and the sets come from the
    honest heads' ids, the liar missing and named."""
    m = SetMatcher(NAMES, deadline=0.5)
    m.add("B", frame(1 + 10**7), 0.0)
    for tid in range(1, 6):
        for n in NAMES:
            m.add(n, frame(tid + 10**7 if n == "B" else tid), tid * 0.01)
    sets = m.pop_ready(1.0)
    assert [(s.trigger_id, s.missing) for s in sets] == [(t, ("B",)) for t in range(1, 6)]
    assert m.stats.implausible == {"B": 6}
