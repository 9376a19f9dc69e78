"""Which fixes a gain continues (app.localization.continuation), frame by frame."""

from __future__ import annotations

from app.localization.continuation import (
    DOUBT_FRAMES,
    GEOMETRY_DOUBT_FRAMES,
    STOP_EXIT_FRAMES,
    Continuation,
    doubt_frames,
)


def _frames(c: Continuation, n: int, *, in_stop: bool = False, search_wait: bool = False) -> None:
    for _ in range(n):
        c.after_frame(
            let_go_for_doubt=False,
            told=False,
            in_stop=in_stop,
            was_told=False,
            search_wait=search_wait,
        )


def test_a_known_start_lasts_until_the_first_fix() -> None:
    c = Continuation(known_start=True)
    _frames(c, 500)
    assert c.active
    c.after_frame(let_go_for_doubt=False, told=True, in_stop=False, was_told=False)
    assert not c.active
    assert not Continuation().active


def test_doubt_lasts_doubt_frames_or_until_the_next_fix() -> None:
    c = Continuation()
    c.after_frame(let_go_for_doubt=True, told=False, in_stop=False, was_told=True)
    _frames(c, DOUBT_FRAMES)
    assert c.active
    _frames(c, 1)
    assert not c.active
    c.doubted()  # a swap onto a place the told radius held
    c.after_frame(let_go_for_doubt=False, told=True, in_stop=False, was_told=False)
    assert not c.active


def test_a_fix_let_go_for_weak_geometry_is_continued_for_longer() -> None:
    assert doubt_frames(("weak geometry",)) == GEOMETRY_DOUBT_FRAMES > DOUBT_FRAMES
    assert doubt_frames(("alternative",)) == doubt_frames(("jump",)) == DOUBT_FRAMES
    c = Continuation()
    c.after_frame(
        let_go_for_doubt=True,
        told=False,
        in_stop=False,
        was_told=True,
        doubt_frames=GEOMETRY_DOUBT_FRAMES,
    )
    _frames(c, GEOMETRY_DOUBT_FRAMES)
    assert c.active
    # ... through a checkpoint too (older ones, without the count, keep DOUBT_FRAMES).
    again = Continuation()
    again.restore(c.checkpoint(levels=False))
    for each in (c, again):
        _frames(each, 1)
        assert not each.active
    state = c.checkpoint(levels=False)
    state.update(since_doubt=DOUBT_FRAMES)
    del state["doubt_frames"]
    again.restore(state)
    _frames(again, 1)
    assert not again.active
    # A swap onto a place the told radius held is plain doubt.
    c.doubted()
    _frames(c, DOUBT_FRAMES + 1)
    assert not c.active


def test_a_fix_let_go_in_a_stop_is_continued_for_stop_exit_frames_out_of_it() -> None:
    c = Continuation()
    # Told as the person came into the stop, let go there: the count starts ...
    c.after_frame(let_go_for_doubt=False, told=False, in_stop=True, was_told=True)
    _frames(c, 40, in_stop=True)  # ... and waits however long the ride takes,
    assert c.active and c.out_of_stop == 0
    _frames(c, STOP_EXIT_FRAMES)  # then runs out of the stop.
    assert c.active
    _frames(c, 1)
    assert not c.active
    # A stop entered with nothing told starts nothing.
    _frames(c, 10, in_stop=True)
    assert not c.active


def test_a_pinned_exit_does_not_count_frames_that_wait_only_for_a_search() -> None:
    c = Continuation()
    c.rode_pinned()
    _frames(c, 10, in_stop=True)  # the car's door wait
    _frames(c, STOP_EXIT_FRAMES - 5)
    # The gain waits only for the evidence tracker's search: the exit is no older for it
    # (searches that find nothing come every 25 frames, the window's length) ...
    _frames(c, 60, search_wait=True)
    assert c.active and c.out_of_stop == STOP_EXIT_FRAMES - 5
    # ... through a checkpoint too.
    again = Continuation()
    again.restore(c.checkpoint(levels=True))
    _frames(again, 10, search_wait=True)
    assert again.active and again.out_of_stop == STOP_EXIT_FRAMES - 5
    # Frames short of anything else count.
    for each in (c, again):
        _frames(each, 6)
        assert not each.active
        _frames(each, 1, in_stop=True)  # (the count ran out: nothing pinned restarts)
        assert not each.active
    # A told fix let go in a stop counts every frame out of it, as before.
    told = Continuation()
    told.after_frame(let_go_for_doubt=False, told=False, in_stop=True, was_told=True)
    _frames(told, STOP_EXIT_FRAMES, search_wait=True)
    assert told.active
    _frames(told, 1, search_wait=True)
    assert not told.active
    # A checkpoint from before the key: the exit counts every frame.
    state = c.checkpoint(levels=True)
    state.update(out_of_stop=3)
    del state["pinned_exit"]
    again.restore(state)
    _frames(again, STOP_EXIT_FRAMES - 3, search_wait=True)
    assert again.active
    _frames(again, 1, search_wait=True)
    assert not again.active


def test_checkpoints_keep_every_count_and_older_ones_resume() -> None:
    c = Continuation(known_start=True)
    c.after_frame(let_go_for_doubt=True, told=False, in_stop=True, was_told=True)
    _frames(c, 3)
    again = Continuation()
    again.restore(c.checkpoint(levels=True))
    assert (again.known_start, again.out_of_stop, again.since_doubt) == (True, 3, 3)
    # One level: no stop to keep; 071f311's checkpoints (a flag beside the count) and
    # older ones without any key continue nothing.
    assert "out_of_stop" not in c.checkpoint(levels=False)
    again.restore({"out_of_stop": 4, "fix_into_stop": False})
    assert not again.active
    again.restore({})
    assert not again.active
