"""The tracker's decode-ahead thread (``rce_gtsam.track.sources.prefetched``): order, bounded look-ahead,
errors in order, and a thread that stops when the consumer does."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from rce_gtsam.track.sources import Frame, prefetched


def _frames(n, produced, fail_at=None):
    for i in range(n):
        if i == fail_at:
            raise ValueError(f"frame {i} is corrupt")
        produced.append(i)
        yield Frame(i, np.zeros((2, 2, 3), np.uint8), i / 30.0)


def test_yields_every_frame_in_order():
    produced = []
    assert [f.index for f in prefetched(_frames(50, produced), depth=3)] == list(range(50))


def test_error_is_raised_after_the_frames_before_it():
    got = []
    with pytest.raises(ValueError, match="frame 7 is corrupt"):
        for f in prefetched(_frames(20, [], fail_at=7), depth=4):
            got.append(f.index)
    assert got == list(range(7))


def test_stopping_early_stops_the_thread_and_bounds_the_look_ahead():
    produced = []
    before = threading.active_count()
    gen = prefetched(_frames(10_000, produced), depth=4)
    assert next(gen).index == 0
    gen.close()
    assert threading.active_count() == before
    assert len(produced) <= 1 + 4 + 1  # the frame handed out, a full buffer, the one being decoded


def test_bad_depth():
    with pytest.raises(ValueError, match="depth"):
        list(prefetched(_frames(1, []), depth=0))
