"""Side-by-side movie of two runs of one demand (e.g. FIFO and MWIS), as the paper's
Supplementary Movie 1: aircraft moving over the network, corridors coloured by how many flights
have used them so far (one colour scale for both panels), approvals counted in the titles.

``python -m uam_sim.movie FIFO.mcap MWIS.mcap --out movie.mp4 [--network NET.yaml]``

Only the recordings' ``/uam/flight_plans`` are read: the simulator flies every approved plan's 4D
trajectory exactly (``uam_sim.world.fleet``), so the aircraft positions at any time follow from the
plans. This also works on recordings that have no fleet states (e.g. ``experiment`` runs).
Corridors are the route segments between consecutive waypoints; with ``--network`` the unused
corridors are drawn too (grey).

Encoding: MP4 (H.264) with the ffmpeg binary that the ``imageio-ffmpeg`` package ships (pinned
in requirements.txt); ``.gif`` outputs, or MP4 when no ffmpeg is found, are written with Pillow.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from uam_contract.stamps import stamp_s
from uam_contract import names
from uam_contract.names import resolved

TOPIC_PLANS = resolved(names.TOPIC_PLANS)
_NS = 1_000_000_000


@dataclass
class RunPlans:
    """The approved flights of one recording: labels and 4D trajectories [s, ENU m]."""

    label: str
    ids: list = field(default_factory=list)
    decided_s: list = field(default_factory=list)
    times_s: list = field(default_factory=list)      # (p,) per flight
    points_m: list = field(default_factory=list)     # (p, 3) per flight
    requests: int = 0
    #: the run's end [s]: the recording's last message (a node-graph run: the simulator's last
    #: step); None when the file has no summary to say it (cut short)
    end_s: float | None = None

    def last_arrival_s(self) -> float:
        return max(float(t[-1]) for t in self.times_s)




def read_plans(path: str | Path, label: str | None = None) -> RunPlans:
    """Approved flight plans of a recording (rclpy decoding). Raises ValueError if it has none."""
    from ..audit.analysis import iter_decoded

    run = RunPlans(label or Path(path).stem)
    seen = set()
    for _topic, _ns, plan in iter_decoded(path, topics=(TOPIC_PLANS,)):
        seen.add(plan.request_id)
        if int(plan.outcome) != 0 or len(plan.waypoints) < 2:
            continue
        run.ids.append(str(plan.request_id))
        run.decided_s.append(stamp_s(plan.header.stamp))
        run.times_s.append(np.array([stamp_s(w.time) for w in plan.waypoints]))
        run.points_m.append(np.array([(w.position.x, w.position.y, w.position.z) for w in plan.waypoints]))
        if label is None and plan.method:
            run.label = plan.method.upper() + (f" ({plan.backend})" if plan.backend else "")
    run.requests = len(seen)
    if not run.ids:
        raise ValueError(f"recording {path}: no approved flight plans on {TOPIC_PLANS}")
    run.end_s = _recording_end_s(path)
    return run


def _recording_end_s(path: str | Path) -> float | None:
    """Log time of the recording's last message [s] (log time is simulation time), from the
    MCAP summary; None if the file has none."""
    from ..recording.mcap_reader import is_complete

    if not is_complete(path):
        return None
    from mcap.reader import make_reader
    with open(path, "rb") as f:
        stats = make_reader(f).get_summary().statistics
    return stats.message_end_time / _NS if stats is not None and stats.message_count else None


#: what ``until`` may name besides a number of seconds
UNTIL_CHOICES = ("end", "arrivals")


def movie_end_s(runs: Sequence[RunPlans], until: str | float = "end") -> float:
    """The movie's last frame time [s]: ``"end"`` the latest run's end (its last arrival when
    the recording does not say), ``"arrivals"`` the last arrival, or a number of seconds."""
    if until == "end":
        return max(r.end_s if r.end_s is not None else r.last_arrival_s() for r in runs)
    if until == "arrivals":
        return max(r.last_arrival_s() for r in runs)
    try:
        t = float(until)
    except (TypeError, ValueError):
        raise ValueError(f"until: {until!r} is not 'end', 'arrivals' or a number of seconds") from None
    if not t > 0:
        raise ValueError(f"until: must be > 0 s, got {until!r}")
    return t


def _seg_key(a: np.ndarray, b: np.ndarray) -> tuple:
    ka, kb = tuple(np.round(a[:2], 0)), tuple(np.round(b[:2], 0))
    return (ka, kb) if ka <= kb else (kb, ka)


class UseCounter:
    """Cumulative flights per corridor (segment between two waypoints, direction ignored)."""

    def __init__(self, segments: dict):
        self.segments = segments          # key -> (2, 2) xy
        self.keys = list(segments)
        self.index = {k: i for i, k in enumerate(self.keys)}

    @classmethod
    def from_runs(cls, runs: Sequence[RunPlans], network: Any = None) -> "UseCounter":
        segs = {}
        if network is not None:
            enu = np.asarray(network.enu_m, dtype=np.float64)
            for u, v in np.asarray(network.edges).reshape(-1, 2):
                segs[_seg_key(enu[u], enu[v])] = np.stack([enu[u][:2], enu[v][:2]])
        for run in runs:
            for pts in run.points_m:
                for a, b in zip(pts[:-1], pts[1:]):
                    key = _seg_key(a, b)
                    if key[0] != key[1]:
                        segs.setdefault(key, np.stack([a[:2], b[:2]]))
        return cls(segs)

    def uses_until(self, run: RunPlans, t_s: float) -> np.ndarray:
        """Per corridor: flights of ``run`` that had entered it by ``t_s``."""
        counts = np.zeros(len(self.keys))
        for times, pts in zip(run.times_s, run.points_m):
            if times[0] > t_s:
                continue
            for j in range(len(pts) - 1):
                if times[j] > t_s:
                    break
                key = _seg_key(pts[j], pts[j + 1])
                if key in self.index:
                    counts[self.index[key]] += 1
        return counts


def positions_at(run: RunPlans, t_s: float) -> np.ndarray:
    """(n, 2) ENU xy of the flights of ``run`` airborne at ``t_s`` (linear between waypoints)."""
    out = []
    for times, pts in zip(run.times_s, run.points_m):
        if times[0] <= t_s <= times[-1]:
            out.append([np.interp(t_s, times, pts[:, 0]), np.interp(t_s, times, pts[:, 1])])
    return np.array(out).reshape(-1, 2)


def ffmpeg_path() -> str | None:
    """The ffmpeg binary of imageio-ffmpeg, else one on PATH, else None."""
    try:
        import imageio_ffmpeg
        return imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError):
        import shutil
        return shutil.which("ffmpeg")


_BACKGROUND, _UNUSED, _SPINE = "#111318", "#444a55", "#333844"


def _panels(runs: list, counter: "UseCounter"):
    """The figure, one panel per run side by side over the corridors' extent [m] with 5 % of
    padding, and per panel its (corridor lines, aircraft dots, title, run)."""
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    xy = np.concatenate([np.stack(list(counter.segments.values())).reshape(-1, 2)])
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    pad = 0.05 * max(hi - lo)
    aspect = float((hi[1] - lo[1] + 2 * pad) / (hi[0] - lo[0] + 2 * pad))
    panel_w = 6.0
    fig, axes = plt.subplots(1, len(runs), figsize=(panel_w * len(runs) + 1.2, panel_w * aspect + 0.9),
                             squeeze=False)
    fig.subplots_adjust(left=0.01, right=0.9, bottom=0.02, top=0.86, wspace=0.03)
    fig.patch.set_facecolor(_BACKGROUND)
    artists = []
    segs = np.stack(list(counter.segments.values()))
    for ax, run in zip(axes[0], runs):
        ax.set_facecolor(_BACKGROUND)
        ax.set_aspect("equal")
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
        ax.set_xticks([])
        ax.set_yticks([])
        lines = LineCollection(segs, colors=_UNUSED, linewidths=1.0)
        ax.add_collection(lines)
        dots = ax.scatter(np.zeros(0), np.zeros(0), s=10, c="#ffffff", edgecolors="none", zorder=3)
        for spine in ax.spines.values():
            spine.set_color(_SPINE)
        title = ax.set_title(run.label, color="white", fontsize=11)
        artists.append((lines, dots, title, run))
    return fig, artists


def _use_colorbar(fig, cmap, vmax: float) -> None:
    """The colour bar of corridor use (flights so far, 0 to ``vmax``) at the figure's right."""
    import matplotlib
    import matplotlib.pyplot as plt

    sm = plt.cm.ScalarMappable(cmap=matplotlib.colors.ListedColormap(cmap(np.linspace(0.25, 1.0, 256))),
                               norm=plt.Normalize(0, vmax))
    cax = fig.add_axes([0.92, 0.1, 0.015, 0.7])
    cbar = fig.colorbar(sm, cax=cax)
    cbar.set_label("flights that used the corridor so far", color="white")
    cbar.ax.yaxis.set_tick_params(color="white", labelcolor="white")


def _frame_drawer(frames: np.ndarray, artists: list, counter: "UseCounter", cmap, vmax: float):
    """The animation's callback: frame ``k`` draws every panel at ``frames[k]`` [s] (corridors
    coloured and widened by their use so far, the aircraft in the air, the title's counts)."""
    import matplotlib

    # Used corridors start a quarter up the colour map, so that one flight already stands out
    # from the unused (grey) ones on the dark background.
    def use_colors(uses: np.ndarray) -> np.ndarray:
        return cmap(0.25 + 0.75 * np.clip(uses / vmax, 0, 1))

    def draw(k: int):
        t = float(frames[k])
        out = []
        for lines, dots, title, run in artists:
            uses = counter.uses_until(run, t)
            colors = np.where(uses[:, None] > 0, use_colors(uses), matplotlib.colors.to_rgba(_UNUSED))
            lines.set_color(colors)
            lines.set_linewidth(np.where(uses > 0, 1.5 + 3.5 * np.clip(uses / vmax, 0, 1), 0.8))
            pos = positions_at(run, t)
            dots.set_offsets(pos if len(pos) else np.zeros((0, 2)))
            approved = sum(1 for d in run.decided_s if d <= t)
            title.set_text(f"{run.label}\nt = {t:.0f} s   approved {approved}   airborne {len(pos)}")
            out += [lines, dots, title]
        return out
    return draw


def _save_animation(anim, fig, out: Path, fps: int, dpi: int) -> Path:
    """Write ``anim`` to ``out``: MP4 (H.264) with the found ffmpeg, else a GIF with Pillow (the
    suffix changed to .gif, said on stderr); returns the written path."""
    import matplotlib
    from matplotlib import animation

    ffmpeg = ffmpeg_path()
    if out.suffix.lower() == ".gif" or ffmpeg is None:
        if out.suffix.lower() != ".gif":
            out = out.with_suffix(".gif")
            print(f"movie: no ffmpeg found; writing a GIF instead: {out}", file=sys.stderr)
        anim.save(str(out), writer=animation.PillowWriter(fps=fps), dpi=dpi,
                  savefig_kwargs={"facecolor": fig.get_facecolor()})
    else:
        matplotlib.rcParams["animation.ffmpeg_path"] = ffmpeg
        writer = animation.FFMpegWriter(fps=fps, codec="libx264", extra_args=[
            # H.264 in yuv420p needs even frame sizes: pad by one pixel where needed
            "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", "-pix_fmt", "yuv420p"])
        anim.save(str(out), writer=writer, dpi=dpi, savefig_kwargs={"facecolor": fig.get_facecolor()})
    return out


def make_movie(paths: Sequence[str | Path], out: str | Path, network: Any = None,
               labels: Sequence[str] | None = None, step_s: float = 10.0, fps: int = 12,
               dpi: int = 100, t_end_s: float | None = None, until: str | float = "end") -> Path:
    """Render the runs side by side into ``out`` (.mp4 or .gif); returns the written path.

    One frame per ``step_s`` of simulated time from 0 to ``t_end_s`` if given, else to
    :func:`movie_end_s` of ``until`` (default: the run's end, not the last arrival after it).
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import animation

    if step_s <= 0:
        raise ValueError(f"step_s: must be > 0, got {step_s}")
    if fps <= 0:
        raise ValueError(f"fps: must be > 0, got {fps}")
    runs = [read_plans(p, labels[i] if labels else None) for i, p in enumerate(paths)]
    counter = UseCounter.from_runs(runs, network)
    t_end = t_end_s if t_end_s is not None else movie_end_s(runs, until)
    frames = np.arange(0.0, t_end + 1e-9, step_s)
    final = [counter.uses_until(r, t_end) for r in runs]
    vmax = max(1.0, max(float(f.max()) for f in final))
    cmap = plt.get_cmap("plasma")
    fig, artists = _panels(runs, counter)
    _use_colorbar(fig, cmap, vmax)
    draw = _frame_drawer(frames, artists, counter, cmap, vmax)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    anim = animation.FuncAnimation(fig, draw, frames=len(frames), blit=False)
    out = _save_animation(anim, fig, out, fps, dpi)
    plt.close(fig)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False, prog="python -m uam_sim.movie",
                                 description="side-by-side movie of runs of one demand (e.g. FIFO and MWIS)")
    ap.add_argument("recordings", nargs="+", help="the runs' .mcap files (two for the paper's movie)")
    ap.add_argument("--out", default="movie.mp4", help=".mp4 (ffmpeg) or .gif")
    ap.add_argument("--network", default="", help="network file, to draw unused corridors as well")
    ap.add_argument("--labels", default="", help="comma-separated panel titles (default: the runs' methods)")
    ap.add_argument("--step-s", type=float, default=10.0, help="simulated seconds per frame")
    ap.add_argument("--fps", type=int, default=12)
    ap.add_argument("--dpi", type=int, default=100)
    ap.add_argument("--until", default="end",
                    help="last frame: 'end' (default: the run's end, its recording's last message), "
                         "'arrivals' (until the last flight landed) or a number of seconds")
    args = ap.parse_args(argv)
    labels = [s.strip() for s in args.labels.split(",")] if args.labels else None
    if labels is not None and len(labels) != len(args.recordings):
        print(f"movie: --labels: {len(labels)} labels for {len(args.recordings)} recordings", file=sys.stderr)
        return 2
    try:
        network = None
        if args.network:
            from uam_planner.network import load_network
            network = load_network(args.network)
        out = make_movie(args.recordings, args.out, network, labels, args.step_s, args.fps, args.dpi,
                         until=args.until)
    except (OSError, ValueError) as exc:
        print(f"movie: {exc}", file=sys.stderr)
        return 1
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
