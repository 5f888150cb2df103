"""The disturbance study's loss-rate bound, from its tables and their provenance.

    python -m uam_sim.reports.safety_report docs/disturbance-study

Reads ``tables.json`` (per Monte-Carlo table: the seeds, the commit that ran it, whether its
seeds were used to find and fix losses, "tuning", or looked at only after, "held-out") and the
tables it names, and writes ``REPORT.md``: the bound on the flown-loss rate per flight and on the
share of runs with a loss, from the held-out seeds alone (the tuning seeds were used to find and
remove every loss, so they cannot bound what remains): from every held-out set together and from
each alone; the seeds no table holds, with what ``tables.json``'s ``gaps`` records of them; and
where a row and the baseline it is compared with ran at different commits.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import pandas as pd

from .stats import binomial_upper

LEVEL = 0.95


def parse_seeds(text: str) -> list:
    """'0-37,45-64' -> [0, ..., 37, 45, ..., 64]."""
    out = []
    for part in str(text).split(","):
        a, _, b = part.strip().partition("-")
        out += list(range(int(a), int(b or a) + 1))
    return out


def _ranges(seeds: list) -> str:
    s = sorted(seeds)
    if not s:
        return "none"
    parts, start = [], s[0]
    for prev, cur in zip(s, s[1:] + [None]):
        if cur != prev + 1:
            parts.append(f"{start}-{prev}" if prev > start else f"{start}")
            start = cur
    return ", ".join(parts)


def _row(df: pd.DataFrame, point: dict) -> pd.Series | None:
    sel = df
    for k, v in point.items():
        sel = sel[(sel[k] - v).abs() < 1e-9]
    return sel.iloc[0] if len(sel) else None


def _bound_text(sets: list, what: str) -> str:
    """The bound on the flown-loss rate per flight and on the share of runs with a loss, from
    (name, row, seeds) of one or more tables at the point."""
    n = sum(int(r["flights"]) for _, r, _ in sets)
    k = sum(int(r["flown_losses"]) for _, r, _ in sets)
    runs = sum(int(r["runs"]) for _, r, _ in sets)
    # a run with a loss has at least one; with k = 0 no run has one
    runs_with = 0 if k == 0 else min(k, runs)
    return (f"{k} flown losses in {n:,} {what} ({runs} runs, seeds "
            f"{_ranges(sorted(s for _, _, ss in sets for s in ss))}): the loss rate is below "
            f"{binomial_upper(k, n, LEVEL):.2e} per flight (rule of three {3 / n:.2e}), and "
            + (f"at most {binomial_upper(runs_with, runs, LEVEL):.1%} of runs have a loss"
               if k == 0 else f"{k} losses in at most {runs_with} of {runs} runs")
            + f" ({LEVEL:.0%}).")


def _gap_lines(man: dict) -> list:
    """The seeds between the least and greatest that no table holds, each range with what
    ``tables.json``'s ``gaps`` records of it (its note, and whether that explains it)."""
    every = sorted({s for t in man["tables"].values() for s in parse_seeds(t["seeds"])})
    gap = sorted(set(range(every[0], every[-1] + 1)) - set(every)) if every else []
    if not gap:
        return ["None: every seed in the range is in a table."]
    notes = man.get("gaps", {})
    noted = {s for seeds in notes for s in parse_seeds(seeds)}
    L = [f"Seeds {_ranges(gap)} are in no table between seed {every[0]} and {every[-1]}."]
    for seeds, g in notes.items():
        if set(parse_seeds(seeds)) & set(gap):
            L += ["", f"Seeds {seeds}: {g['note']}"
                  + ("" if g.get("explained") else " Why they were left out is not recorded, so "
                     "their absence is unexplained.")]
    rest = sorted(set(gap) - noted)
    if rest:
        L += ["", f"Seeds {_ranges(rest)}: neither the tables nor the history that committed them "
              "says why, so their absence is unexplained."]
    return L


def report_text(d: Path) -> str:
    man = json.loads((d / "tables.json").read_text(encoding="utf-8"))
    point = man["point"]
    L = ["# Disturbance study: the flown-loss bound", "",
         "Written by `uam_sim.reports.safety_report` from `tables.json` and the tables it names "
         f"(`python -m uam_sim.reports.safety_report {d.as_posix()}`). Point: speed error "
         f"{point['speed_error']:.0%}, spatial buffer {point['spatial_buffer_m']:.0f} m, with the "
         "conflict probe. Bounds are one-sided exact binomial (Clopper-Pearson) at "
         f"{LEVEL:.0%}; with no event that is 1 - 0.05^(1/n), about 3 / n (the rule of three).", ""]
    rows, held, tuning = [], [], []
    for name, t in man["tables"].items():
        df = pd.read_csv(d / name)
        r = _row(df, point)
        seeds = parse_seeds(t["seeds"])
        rows.append([name, t["role"], _ranges(seeds), f"`{t['code']}`", t["what"],
                     "-" if r is None else f"{int(r['flights']):,}",
                     "-" if r is None else int(r["flown_losses"])])
        if r is not None and "probe_updates" in r and r["probe_updates"] == r["probe_updates"] \
                and r["probe_updates"] > 0:
            (held if t["role"] == "held-out" else tuning).append((name, r, seeds))
    L += ["| table | seeds' role | seeds | commit | what | flights at the point | flown losses |",
          "|---|---|---|---|---|---|---|"]
    L += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    L += ["", "## The bound, held-out seeds only", ""]
    if held:
        codes = sorted({man["tables"][name]["code"] for name, _, _ in held})
        L.append(_bound_text(held, "held-out flights")
                 + ("" if len(held) == 1 else
                    (" Both held-out sets together" if len(held) == 2 else f" All {len(held)} held-out sets together")
                    + "; they ran at "
                    + ", ".join(f"`{c}`" for c in codes)
                    + (", so pooling them assumes the commits between fly the same"
                       if len(codes) > 1 else "") + "."))
        if len(held) > 1:
            L += ["", "Each held-out set alone:", ""]
            L += [f"- `{name}` (`{man['tables'][name]['code']}`): " + _bound_text([(name, r, ss)], "flights")
                  for name, r, ss in held]
    else:
        L.append("No held-out table at this point: no valid bound.")
    if tuning:
        n_t = sum(int(r["flights"]) for _, r, _ in tuning)
        k_t = sum(int(r["flown_losses"]) for _, r, _ in tuning)
        L += ["", f"Not a bound: the tuning seeds ({k_t} flown losses in {n_t:,} flights at this "
              "point) are the ones every loss was found and fixed on; pooling them with the "
              "held-out ones would claim a bound "
              f"({binomial_upper(k_t + sum(int(r['flown_losses']) for _, r, _ in held), n_t + sum(int(r['flights']) for _, r, _ in held)):.2e}) "
              "the held-out seeds alone do not give."]
    L += ["", "## Seeds no table holds", "", *_gap_lines(man)]
    L += ["", "## Rows compared with a baseline at another commit", ""]
    mism = [(name, t, man["tables"][t["baseline"]]) for name, t in man["tables"].items()
            if t.get("baseline") and man["tables"][t["baseline"]]["code"] != t["code"]]
    L += [f"- `{name}` ({t['what']}) ran at `{t['code']}`, its baseline `{t['baseline']}` at "
          f"`{b['code']}`: its cost against that baseline mixes the change between the two commits "
          "with the buffer's." for name, t, b in mism] or ["None."]
    return "\n".join(L) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="safety_report", description=__doc__.split("\n\n")[0])
    ap.add_argument("dir", nargs="?", default="docs/disturbance-study")
    d = Path(ap.parse_args(argv).dir)
    if not (d / "tables.json").exists():
        print(f"safety_report: {d / 'tables.json'}: not found", file=sys.stderr)
        return 2
    (d / "REPORT.md").write_text(report_text(d), encoding="utf-8")
    print(d / "REPORT.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
