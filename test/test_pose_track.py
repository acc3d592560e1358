"""PoseTrack: where a probe is at a frame's time, from poses that arrive in bursts."""
import numpy as np
import pytest

from paper_sim_ros.pose_track import MAX_EXTRAPOLATION_NS, PoseTrack

MS = 1_000_000


def track_of(*stamped) -> PoseTrack:
    track = PoseTrack()
    for stamp_ms, x in stamped:
        track.add(stamp_ms * MS, np.array([x, 0.0, 0.0]))
    return track


def test_a_burst_of_poses_gives_an_even_path():
    """A probe at 0.1 m/s published at 60 Hz, the poses read three at a time: sampled at
    each frame's time it moves 1/600 m a frame, not 0, 0, 5 mm."""
    track = PoseTrack()
    frames = []
    for burst in range(10):
        for k in range(3):
            stamp = (3 * burst + k) * 1e3 / 60
            track.add(int(stamp * MS), np.array([0.1 * stamp / 1e3, 0.0, 0.0]))
        for k in range(3):  # the frames of this burst, the last one a frame after its poses
            frames.append(track.at(int((3 * burst + k + 1) * 1e3 / 60 * MS))[0])
    np.testing.assert_allclose(np.diff(frames), 0.1 / 60, rtol=1e-6)


def test_between_poses_it_interpolates_and_before_them_it_holds_the_oldest():
    track = track_of((0, 0.0), (10, 1.0), (30, 3.0))
    assert track.at(5 * MS)[0] == pytest.approx(0.5)
    assert track.at(20 * MS)[0] == pytest.approx(2.0)
    assert track.at(-5 * MS)[0] == 0.0


def test_past_the_newest_it_extrapolates_a_little_and_only_from_close_poses():
    moving = track_of((0, 0.0), (10, 1.0))
    assert moving.at(15 * MS)[0] == pytest.approx(1.5)
    assert moving.at(10 * MS + 10 * MAX_EXTRAPOLATION_NS)[0] == pytest.approx(
        1.0 + MAX_EXTRAPOLATION_NS / (10 * MS))
    far_apart = track_of((0, 0.0), (300, 1.0))  # a node far behind reads poses seldom
    assert far_apart.at(350 * MS)[0] == 1.0
    assert track_of((0, 2.0)).at(50 * MS)[0] == 2.0


def test_a_pose_stamped_earlier_than_the_newest_starts_afresh():
    track = track_of((100, 5.0), (110, 6.0), (50, -1.0))
    assert len(track) == 1 and track.at(200 * MS)[0] == -1.0
