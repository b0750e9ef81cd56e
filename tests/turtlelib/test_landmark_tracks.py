"""LandmarkTracks: the count of tentative rows behind ``all_confirmed`` follows every change of the rows."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from turtlelib.estimation.landmark_tracks import LandmarkTracks


def test_all_confirmed_hand_case():
    tracks = LandmarkTracks(capacity=2)
    assert tracks.all_confirmed
    tracks.append(np.array([4, 7]), stamp_ns=10, confirmed=False)
    tracks.append(np.array([9]), stamp_ns=10, confirmed=True)
    assert not tracks.all_confirmed
    # a second sighting (confirm_count 2) confirms id 7 at slot 1; slot 0 (id 4) stays tentative
    assert tracks.sighted(np.array([1]), confirm_count=2, stamp_ns=20).tolist() == [7]
    assert not tracks.all_confirmed
    assert tracks.expired(stamp_ns=30, timeout_ns=20).tolist() == [0]
    tracks.remove(0)
    assert tracks.all_confirmed
    assert tracks.expired(stamp_ns=30, timeout_ns=0).tolist() == []


# one change each: ("append", k, confirmed) | ("sight", slot) | ("remove", slot)
CHANGES = st.lists(
    st.one_of(
        st.tuples(st.just("append"), st.integers(0, 3), st.booleans()),
        st.tuples(st.just("sight"), st.integers(0, 40)),
        st.tuples(st.just("remove"), st.integers(0, 40)),
    ),
    max_size=40,
)


@settings(max_examples=200, deadline=None)
@given(CHANGES)
def test_all_confirmed_follows_appends_sightings_and_removals(changes):
    tracks = LandmarkTracks(capacity=1)
    for stamp_ns, change in enumerate(changes):
        n = len(tracks.ids)
        if change[0] == "append":
            ids = np.arange(tracks.next_id, tracks.next_id + change[1])
            tracks.append(ids, stamp_ns, confirmed=change[2])
        elif change[0] == "sight" and n:
            tracks.sighted(np.array([change[1] % n]), confirm_count=2, stamp_ns=stamp_ns)
        elif change[0] == "remove" and n:
            tracks.remove(change[1] % n)
        assert tracks.all_confirmed == bool(tracks.confirmed.all())
        expired = tracks.expired(stamp_ns + 1, timeout_ns=0)
        assert expired.tolist() == (~tracks.confirmed).nonzero()[0][::-1].tolist()
