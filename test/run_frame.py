"""What a recording of a run that ended as planned holds beside its plans, for tests that write
recordings by hand: the simulator's epoch announcements with its end, the run's airspace record
and a passing recorder check (uam_sim.audit.analysis.run_problems asks for all of them)."""

from __future__ import annotations

NS = 1_000_000_000


def complete_run(rec, epochs: int = 1, epoch_s: float = 30.0, duration_s: float | None = None,
                 airspace: dict | None = None, airspace_record: bool = True, end_s: float | None = None, session: str = "sim0", planner: str = "") -> None:
    """Write into McapRecorder ``rec`` the frame of a run of ``epochs`` epochs that ended as planned."""
    from builtin_interfaces.msg import Time
    from uam_msgs.msg import EpochSync

    from uam_sim.audit.separation import AIRSPACE_METADATA, airspace_metadata

    duration = float(duration_s if duration_s is not None else epochs * epoch_s)
    if not rec.has_topic("/uam/epoch_sync"):
        rec.add_topic("/uam/epoch_sync", EpochSync)
    partners = [f"planner={planner}"] if planner else []

    def sync(k, t, finished=False):
        return EpochSync(epoch_index=k, epoch_time=Time(sec=int(t), nanosec=int(round((t % 1) * 1e9))),
                         sender="simulator", finished=finished, session=session, partners=partners,
                         duration_s=duration, epoch_s=float(epoch_s))

    for k in range(epochs):
        rec.write("/uam/epoch_sync", sync(k, k * epoch_s), int(k * epoch_s * NS))
    end = duration if end_s is None else float(end_s)
    rec.write("/uam/epoch_sync", sync(epochs, end, finished=True), int(end * NS))
    if airspace_record:
        rec.add_metadata(AIRSPACE_METADATA, airspace or airspace_metadata("sphere", 100.0, 30.0, 0.0))
    rec.add_metadata("uam_recorder_check", {"ok": "true", "verdict": "a recording written by a test"})
