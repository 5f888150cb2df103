"""Facts the README and the docs state that drift when the code changes: how many nodes
run_fleet.sh starts by default, the date a player shows for a recording, the study folders the
README points to, and the recommended disturbance settings. Plain text checks, no ROS."""

from __future__ import annotations

import pathlib
import re

from uam_contract.stamps import DEFAULT_SCENARIO_START_UTC

ROOT = pathlib.Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
NUMBERS = {"four": 4, "five": 5, "six": 6, "seven": 7}


def _default_nodes() -> list[str]:
    """The log names of the nodes run_fleet.sh starts whatever the options: its ``start`` lines at
    the top level of the script (the conditional ones are indented)."""
    script = (ROOT / "scripts" / "run_fleet.sh").read_text()
    return re.findall(r"^start \S+ \S+ (\S+)", script, flags=re.M)


def test_the_readme_names_the_nodes_run_fleet_starts_by_default():
    nodes = _default_nodes()
    assert len(nodes) >= 4, nodes  # the test reads the script
    m = re.search(r"starts (\w+) nodes \(([^)]*)\)", README)
    assert m, "the README no longer says how many nodes run_fleet.sh starts"
    assert NUMBERS[m.group(1)] == len(nodes), (m.group(0), nodes)
    named = {n.strip().replace(" ", "_") for n in m.group(2).split(",")}
    assert named == set(nodes), (named, nodes)


def test_every_date_a_player_shows_is_the_default_scenario_start():
    """A recording's log times start at the recorder's log_time_start_utc (its default is
    DEFAULT_SCENARIO_START_UTC), so players show that date, not 1970."""
    day = DEFAULT_SCENARIO_START_UTC[:10]
    claims = []
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        text = " ".join(path.read_text().split())
        claims += [(path.name, d) for d in re.findall(r"(?:players?|timeline)(?:'s timeline)? shows? (\d{4}-\d\d-\d\d)", text)]
    assert claims, "no doc says what a player shows"
    assert all(d == day for _, d in claims), claims


def test_the_readme_links_every_study_folder():
    studies = sorted(p.name for p in (ROOT / "docs").iterdir() if p.is_dir() and p.name.endswith("-study"))
    assert studies, "no study folder found"
    missing = [s for s in studies if f"docs/{s}/" not in README]
    assert missing == [], f"study folders the README does not link: {missing}"


def test_the_recommended_disturbance_settings_are_the_same_in_the_readme_and_the_docs():
    table = (ROOT / "docs" / "disturbances.md").read_text()
    row = next(line for line in table.splitlines() if "(recommended)" in line)
    flags = re.search(r"`(--[^`]+)`", row).group(1)
    assert f"`{flags}`" in README, flags


def test_the_readme_picture_is_made_by_its_script_from_a_real_run():
    """The README's picture is the output of scripts/make_readme_picture.sh (a run of the node
    graph rendered by the headless viewer), the README names that command, and the picture is a
    small 1400x800 PNG."""
    from PIL import Image

    script = ROOT / "scripts" / "make_readme_picture.sh"
    assert script.is_file() and script.stat().st_mode & 0o111, f"{script}: missing or not executable"
    body = script.read_text()
    picture = re.search(r"^OUT=(\S+)$", body, flags=re.M).group(1)
    assert "scripts/run_fleet.sh" in body and "uam_sim.views.screenshot" in body, script
    shown = re.search(r"^!\[[^]]*\]\(([^)]+)\)", README, flags=re.M).group(1)
    assert shown == picture, (shown, picture)
    assert "scripts/make_readme_picture.sh" in README
    path = ROOT / picture
    assert path.stat().st_size < 400_000, f"{picture}: {path.stat().st_size} bytes"
    assert Image.open(path).size == (1400, 800), Image.open(path).size
