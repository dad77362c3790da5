"""StampSync: frames matched by exact stamps, released in order and never twice; late inputs ignored;
a producer's 'not coming' releases a frame; frames that cannot complete are reported with what they miss."""

import pytest

from simreal_nodes.sync import TIME_JUMP_NS, StampSync, live_skip_reason


def stamps(ready):
    return [s for s, _ in ready]


def test_a_frame_is_released_when_its_required_inputs_are_in():
    s = StampSync(("image", "obs"))
    assert s.add("image", 10, "i10") == []
    assert s.add("obs", 10, "o10") == [(10, {"image": "i10", "obs": "o10"})]
    assert s.pop_dropped() == []


def test_optional_input_is_waited_for_then_given_up_after_newer_frames():
    s = StampSync(("image",), ("p",), wait=1)
    assert s.add("image", 1, "i1") == []  # waits for p
    assert s.add("p", 1, "p1") == [(1, {"image": "i1", "p": "p1"})]
    assert s.add("image", 2, "i2") == []
    # one newer complete frame: frame 2 goes without its optional input, frame 3 waits
    assert stamps(s.add("image", 3, "i3")) == [2]


def test_a_late_optional_input_does_not_open_a_frame_that_is_later_dropped():
    """Regression: parameters arriving after their frame was drawn without them made a new frame with only
    the parameters, later reported as dropped: a frame both drawn and dropped."""
    s = StampSync(("image",), ("p",), wait=1)
    s.add("image", 1, "i1")
    assert stamps(s.add("image", 2, "i2")) == [1]
    assert s.add("p", 1, "p1") == []
    assert s.late == 1
    for k in range(3, 40):
        s.add("image", k, f"i{k}")
        s.add("p", k, f"p{k}")
    assert s.pop_dropped() == []


def test_give_up_releases_a_frame_waiting_for_an_input_that_will_not_come():
    s = StampSync(("image",), ("p",), wait=10**9)  # lossless: wait for every input
    s.add("image", 1, "i1")
    assert s.give_up("p", 1) == [(1, {"image": "i1"})]
    # the word can come before the frame's other inputs
    assert s.give_up("p", 2) == []
    assert s.add("image", 2, "i2") == [(2, {"image": "i2"})]
    assert s.give_up("p", 1) == []  # already out: nothing happens
    with pytest.raises(KeyError):
        s.give_up("image", 3)


def test_older_frames_are_released_before_a_newer_one_or_dropped_with_what_they_miss():
    s = StampSync(("image", "obs"), ("p",), wait=2)
    s.add("image", 1, "i1")
    s.add("obs", 1, "o1")  # complete, waits for p
    s.add("image", 2, "i2")  # never gets its obs
    s.add("image", 3, "i3")
    ready = s.add("obs", 3, "o3")
    assert ready == []  # 1 and 3 wait for p
    ready = s.add("p", 3, "p3")
    assert stamps(ready) == [1, 3]  # 1 goes out first, without p
    assert s.pop_dropped() == [(2, "incomplete frame (missing obs)")]
    assert s.add("obs", 2, "o2") == [] and s.late == 1


def test_too_many_pending_frames_drop_the_oldest():
    s = StampSync(("image", "obs"), max_pending=3)
    for k in range(5):
        s.add("image", k, k)
    assert [d[0] for d in s.pop_dropped()] == [0, 1]
    assert s.add("obs", 0, "o0") == []  # that frame is gone: late, not reopened


def test_stamps_jumping_back_restart_the_synchronizer():
    s = StampSync(("image",))
    big = 100 * TIME_JUMP_NS
    assert stamps(s.add("image", big, "a")) == [big]
    assert stamps(s.add("image", 1, "looped")) == [1]
    assert s.late == 0


def test_a_complete_frame_dropped_while_it_waits_says_what_it_waited_for():
    from simreal_nodes.sync import StampSync

    sync = StampSync(("image",), ("depth",), wait=5, max_pending=2)
    for s in (1, 2, 3):
        assert sync.add("image", s, object()) == []
    assert sync.pop_dropped() == [(1, "frame held for depth and over 2 frames pending")]


def test_a_live_skip_says_a_missing_input_may_have_been_shed():
    s = StampSync(("image",), ("depth",), wait=0, max_pending=1)
    s.add("depth", 1, "d1")
    s.add("depth", 2, "d2")  # frame 1 never got its image (replaced while the node was busy): over max_pending
    (stamp, why), = s.pop_dropped()
    assert stamp == 1 and why == "incomplete frame (missing image)"
    live = live_skip_reason(why)
    assert live.startswith("incomplete frame (missing image: replaced in the live queue") and live.endswith(")")
    assert live_skip_reason("the stamps jumped back (source restarted)") == "the stamps jumped back (source restarted)"
