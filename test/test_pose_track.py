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


def test_a_probe_placed_past_its_poses_closes_the_gap_over_frames_not_in_one():
    """A node behind the clock steps frames past its newest pose (too old to extrapolate
    from: the probe is held), then poses come that put the probe further along. Placed,
    the probe goes on from where it was held and closes the gap over a few frames; read
    from the track alone it would jump the whole gap in one frame."""
    frame_ns, frame_seconds = int(1e9 / 60), 1 / 60
    speed = 0.2  # m/s
    track = track_of((0, 0.0), (150, speed * 0.150))
    placed = [track.place(k * frame_ns, frame_seconds)[0] for k in range(9, 18)]  # held
    assert placed[-1] == pytest.approx(speed * 0.150)
    for stamp_ms in (200, 250, 300, 350, 400):  # the poses the tick could not read
        track.add(stamp_ms * MS, np.array([speed * stamp_ms / 1e3, 0.0, 0.0]))
    read_jump = track.at(18 * frame_ns)[0] - placed[-1]
    placed += [track.place(k * frame_ns, frame_seconds)[0] for k in range(18, 48)]
    strides = np.diff(placed[8:])
    assert read_jump > 0.015
    assert strides.max() < speed * frame_seconds + read_jump / 4, \
        f'a stride of {1e3 * strides.max():.1f} mm against a gap of {1e3 * read_jump:.1f} mm'
    assert np.all(strides > 0.0), 'the probe went back'
    # half a second on it is where its poses put it (to half a millimetre)
    assert placed[-1] == pytest.approx(track.at(47 * frame_ns)[0], abs=5e-4)


def test_a_placement_forgotten_starts_where_the_poses_are():
    track = track_of((0, 0.0), (10, 0.0))
    assert track.place(30 * MS, 1 / 60)[0] == 0.0  # past the newest pose, held
    track.add(35 * MS, np.array([0.5, 0.0, 0.0]))  # it was at 0.4 then
    assert track.place(50 * MS, 1 / 60)[0] < track.at(50 * MS)[0] - 0.3  # catching up
    track.forget_placement()
    assert track.place(60 * MS, 1 / 60)[0] == track.at(60 * MS)[0]


def test_a_flood_of_poses_shorter_than_a_tick_still_places_an_even_path():
    """Poses every millisecond, a tick every 4 frames: the track keeps the last 32 poses,
    less than a tick, so a tick's first frames are older than its oldest pose. The probe,
    at an even 0.1 m/s, still moves 1/600 m a frame from the first tick's last frame on
    (before it, nothing was placed: the first frames hold the oldest pose)."""
    track = PoseTrack()
    frame_ns = int(1e9 / 60)
    placed = []
    for tick in range(6):
        for stamp_ms in range(tick * 67, (tick + 1) * 67):
            track.add(stamp_ms * MS, np.array([0.1 * stamp_ms / 1e3, 0.0, 0.0]))
        for frame in range(4 * tick + 1, 4 * tick + 5):
            placed.append(track.place(frame * frame_ns, 1 / 60)[0])
    np.testing.assert_allclose(np.diff(placed[3:]), 0.1 / 60, atol=2e-5)
