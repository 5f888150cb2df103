"""The side-by-side movie: corridor use and positions from the plans, frames in the file."""

from __future__ import annotations

import numpy as np
import pytest

from uam_sim.views.movie import RunPlans, UseCounter, main, make_movie, positions_at


def one_flight_run() -> RunPlans:
    """A flight A(0,0) -> B(1000,0) -> C(1000,1000), 100 s per leg, departing at 10 s."""
    return RunPlans("test", ids=["r1"], decided_s=[0.0], times_s=[np.array([10.0, 110.0, 210.0])],
                    points_m=[np.array([[0.0, 0, 5], [1000.0, 0, 120], [1000.0, 1000, 5]])])


def test_corridor_use_counts_flights_that_entered_each_segment():
    run = one_flight_run()
    counter = UseCounter.from_runs([run])
    assert len(counter.keys) == 2
    ab = counter.index[min(counter.keys, key=lambda k: k[1][1])]   # the segment along y = 0
    bc = 1 - ab
    assert counter.uses_until(run, 5.0).tolist() == [0, 0]
    u = counter.uses_until(run, 50.0)
    assert (u[ab], u[bc]) == (1, 0)
    u = counter.uses_until(run, 150.0)
    assert (u[ab], u[bc]) == (1, 1)


def test_positions_interpolate_the_plan_and_drop_landed_flights():
    run = one_flight_run()
    np.testing.assert_allclose(positions_at(run, 60.0), [[500.0, 0.0]])
    np.testing.assert_allclose(positions_at(run, 160.0), [[1000.0, 500.0]])
    assert positions_at(run, 211.0).shape == (0, 2) and positions_at(run, 9.0).shape == (0, 2)


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory):
    pytest.importorskip("uam_msgs.msg", reason="needs the built workspace (source scripts/env.sh)")
    from view_runs import record_run

    tmp = tmp_path_factory.mktemp("movie")
    paths = []
    for method in ("fifo", "greedy"):
        path = tmp / f"{method}.mcap"
        record_run(path, method, rate=4.0, duration_s=120.0, views=False)
        paths.append(path)
    return paths


def _expected_frames(paths, step_s):
    from uam_sim.views.movie import read_plans
    t_end = max(float(t[-1]) for p in paths for t in read_plans(p).times_s)
    return len(np.arange(0.0, t_end + 1e-9, step_s))


def test_gif_has_one_frame_per_step(two_runs, tmp_path):
    from PIL import Image

    out = make_movie(two_runs, tmp_path / "m.gif", step_s=60.0, fps=4, dpi=50)
    with Image.open(out) as im:
        assert im.n_frames == _expected_frames(two_runs, 60.0) > 3
        assert im.size[0] > 1.5 * im.size[1]   # two panels side by side


def test_mp4_is_written_with_the_pinned_ffmpeg(two_runs, tmp_path):
    imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")
    out = make_movie(two_runs, tmp_path / "m.mp4", step_s=60.0, fps=4, dpi=50)
    assert out.suffix == ".mp4"
    frames, _secs = imageio_ffmpeg.count_frames_and_secs(str(out))
    assert frames == _expected_frames(two_runs, 60.0)


def test_cli_names_bad_input(two_runs, tmp_path, capsys):
    assert main([str(p) for p in two_runs] + ["--labels", "only-one", "--out", str(tmp_path / "x.gif")]) == 2
    assert "--labels: 1 labels for 2 recordings" in capsys.readouterr().err
    from uam_sim.recording import McapRecorder
    empty = tmp_path / "empty.mcap"
    with McapRecorder(empty) as rec:
        rec.add_topic("/uam/flight_plans", "uam_msgs/msg/FlightPlan")
    assert main([str(empty), "--out", str(tmp_path / "y.gif")]) == 1
    assert "no approved flight plans" in capsys.readouterr().err
    with pytest.raises(ValueError, match="step_s: must be > 0"):
        make_movie(two_runs, tmp_path / "z.gif", step_s=0.0)


def test_the_movie_stops_at_the_run_s_end_unless_told_otherwise(tmp_path):
    """The movie played on to the last arrival: 88 % of a 600 s run's movie came after the run."""
    pytest.importorskip("uam_msgs.msg", reason="needs the built workspace (source scripts/env.sh)")
    from PIL import Image
    from view_runs import record_run
    from uam_sim.views.movie import movie_end_s, read_plans

    path = tmp_path / "cut.mcap"
    record_run(path, "greedy", rate=4.0, duration_s=120.0, views=False, stop_s=90.0)
    run = read_plans(path)
    assert run.end_s == pytest.approx(90.0) and run.last_arrival_s() > 120.0
    assert movie_end_s([run]) == pytest.approx(90.0)
    assert movie_end_s([run], "arrivals") == pytest.approx(run.last_arrival_s())
    assert movie_end_s([run], "45") == 45.0
    with pytest.raises(ValueError, match="until: 'later'"):
        movie_end_s([run], "later")
    assert main([str(path), "--out", str(tmp_path / "end.gif"), "--step-s", "30", "--dpi", "40"]) == 0
    with Image.open(tmp_path / "end.gif") as im:
        assert im.n_frames == 4  # t = 0, 30, 60, 90 s
    assert main([str(path), "--out", str(tmp_path / "all.gif"), "--step-s", "30", "--dpi", "40",
                 "--until", "arrivals"]) == 0
    with Image.open(tmp_path / "all.gif") as im:
        assert im.n_frames == len(np.arange(0.0, run.last_arrival_s() + 1e-9, 30.0))
