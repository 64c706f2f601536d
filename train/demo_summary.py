"""The summary ``make demo`` ends with: ``python -m train.demo_summary results``.

It reads what the demo's commands wrote and prints, for a reader who has not opened a file yet:

* each paper reproduction's claims, held / failed: every row of the claims table of ``<paper>/report.md``
  (where there is no report, ``<paper>/metrics.json``'s ``claims``);
* each leaderboard's target verdict (the ``Target:`` line of ``leaderboard.md``);
* where the files are;
* how long each stage took, their sum and the wall clock from the first start to the last end
  (``.demo_times``: one line ``START END STAGE`` per stage, Unix-second stamps written by ``train.demo``).

Nothing here raises on a missing or unreadable file: the summary says what is missing instead.
"""

from __future__ import annotations

import glob
import json
import os
import re
import sys

PAPERS = ("zhao2020", "fu2017", "wang2019", "wan2014", "gao2016")
TIMES = ".demo_times"


def _flatten(claims: dict) -> list[tuple[str, bool]]:
    """``{claim: bool}`` or ``{setting: {claim: bool}}`` (fu2017) as ``[(name, holds)]``."""
    out = []
    for claim, value in claims.items():
        if isinstance(value, dict):
            out += [(f"{claim}.{name}", bool(v)) for name, v in value.items()]
        else:
            out.append((str(claim), bool(value)))
    return out


def _report_claims(path: str) -> list[tuple[str, bool]] | None:
    """The rows of every claims table of a report (a table whose header's last cell is ``holds``, e.g.
    ``| claim | our numbers | criterion | holds |``; a ``setting`` column is appended to the claim's name), or
    None when it has none or cannot be read."""
    try:
        with open(path) as fh:
            lines = fh.read().splitlines()
    except OSError:
        return None
    claims, found, inside, setting = [], False, False, None
    for line in lines:
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("|") and cells[-1] == "holds":
            inside = found = True
            setting = cells.index("setting") if "setting" in cells else None  # a claim checked per setting
            continue
        if inside and line.startswith("|"):
            if set(cells[0]) <= {"-", ":"}:
                continue
            name = cells[0] if setting is None else f"{cells[0]} ({cells[setting]})"
            claims.append((name, cells[-1].strip("*") == "yes"))
        else:
            inside = False
    return claims if found else None


def _metrics_claims(path: str) -> list[tuple[str, bool]] | None:
    """``metrics.json``'s ``claims`` flattened, or None when it has none or cannot be read."""
    try:
        with open(path) as fh:
            claims = json.load(fh).get("claims")
    except (OSError, ValueError, AttributeError):
        return None
    return _flatten(claims) if isinstance(claims, dict) and claims else None


def paper_claims(folder: str, paper: str) -> tuple[list[tuple[str, bool]] | None, str]:
    """(claims, where they were read or what is missing) of one reproduction: every row of the claims tables
    of ``report.md`` (what its reader sees), else ``metrics.json``'s ``claims``. Where both exist and count
    differently, ``where`` says so (the two files of one run should list the same claims)."""
    base = os.path.join(folder, paper)
    metrics_path, report_path = os.path.join(base, "metrics.json"), os.path.join(base, "report.md")
    from_report, from_metrics = _report_claims(report_path), _metrics_claims(metrics_path)
    if from_report is not None:
        where = report_path
        if from_metrics is not None and len(from_metrics) != len(from_report):
            where += f"; metrics.json lists {len(from_metrics)} of its {len(from_report)} claims"
        return from_report, where
    if from_metrics is not None:
        return from_metrics, metrics_path
    if not os.path.isdir(base):
        return None, f"missing: {base}/ (not reproduced)"
    return None, f"missing: no claims in {metrics_path} or {report_path}"


def leaderboard_verdicts(folder: str) -> tuple[list[tuple[str, str]] | None, str]:
    """[(leaderboard section, its target verdict)] from ``leaderboard.md``, or (None, what is missing)."""
    path = os.path.join(folder, "leaderboard.md")
    try:
        with open(path) as fh:
            text = fh.read()
    except OSError:
        return None, f"missing: {path}"
    verdicts = []
    for section in re.split(r"^## ", text, flags=re.M)[1:]:
        title = section.splitlines()[0].strip()
        target = next((line for line in section.splitlines() if line.startswith("Target:")), None)
        if target is None:
            verdicts.append((title, "no trained model evaluated (no target verdict)"))
        elif target.rstrip(".").endswith("**not met**"):
            verdicts.append((title, "target not met"))
        elif target.rstrip(".").endswith("**met**"):
            verdicts.append((title, "target met"))
        else:
            verdicts.append((title, target[len("Target: "):][:100]))
    return verdicts, path


def _records(folder: str) -> tuple[list[tuple[int, int, str]] | None, str]:
    """[(start, end, stage)] from ``.demo_times``, or (None, what is missing). Malformed lines are skipped."""
    path = os.path.join(folder, TIMES)
    try:
        with open(path) as fh:
            lines = fh.read().splitlines()
    except OSError:
        return None, f"missing: {path} (run `make demo` to time the stages)"
    records = []
    for line in lines:
        parts = line.split(maxsplit=2)
        if len(parts) == 3 and parts[0].isdigit() and parts[1].isdigit():
            records.append((int(parts[0]), int(parts[1]), parts[2]))
    return records, path


def stage_times(folder: str) -> tuple[list[tuple[str, int]] | None, int | None, str]:
    """([(stage, seconds)], wall-clock seconds, where) from ``.demo_times``, or (None, None, what is missing).
    The wall clock runs from the first stage's start to the last one's end (the demo runs stages side by
    side, so it is less than their sum; None without a stage). Malformed lines are skipped."""
    records, where = _records(folder)
    if records is None:
        return None, None, where
    wall = max(e for _, e, _ in records) - min(s for s, _, _ in records) if records else None
    return [(stage, end - start) for start, end, stage in records], wall, where


def _duration(seconds: int) -> str:
    minutes, sec = divmod(max(seconds, 0), 60)
    return f"{minutes} min {sec:02d} s" if minutes else f"{sec} s"


def summary(folder: str) -> str:
    lines = [f"== demo summary ({folder}) ==", "", "Paper reproductions (claims held / failed):"]
    for paper in PAPERS:
        claims, where = paper_claims(folder, paper)
        if claims is None:
            lines.append(f"  {paper:<9} {where}")
            continue
        failed = [name for name, holds in claims if not holds]
        held = len(claims) - len(failed)
        note = f"; failed: {', '.join(failed)}" if failed else ""
        incomplete = " (INCOMPLETE: interrupted run)" if os.path.exists(os.path.join(folder, paper, "INCOMPLETE")) \
            else ""
        lines.append(f"  {paper:<9} {held} held, {len(failed)} failed{note}{incomplete}  [{where}]")

    lines += ["", "Leaderboards (trained policy against the strongest realizable baseline):"]
    verdicts, where = leaderboard_verdicts(folder)
    if verdicts is None:
        lines.append(f"  {where}")
    elif not verdicts:
        lines.append(f"  no leaderboard sections in {where}")
    else:
        width = max(len(t) for t, _ in verdicts)
        lines += [f"  {title:<{width}}  {text}" for title, text in verdicts]

    lines += ["", "Files:"]
    found = [
        (os.path.join(folder, "leaderboard.md"), "leaderboards with every verdict"),
        *((os.path.join(folder, p, "report.md"), f"{p}: claims, numbers, departures") for p in PAPERS),
    ]
    for path, what in found:
        lines.append(f"  {path:<32} {what}" if os.path.isfile(path) else f"  {path:<32} missing")
    figures = sorted(glob.glob(os.path.join(folder, "*", "*.png")))
    curves = sorted(glob.glob(os.path.join(folder, "train", "*", "seed*", "learning_curve.png")))
    lines.append(f"  {len(figures)} figures in {folder}/<paper or leaderboard>/*.png, "
                 f"{len(curves)} learning curves in {folder}/train/<scenario>/seed*/learning_curve.png")

    lines += ["", "Stage times:"]
    stages, wall, where = stage_times(folder)
    if stages is None:
        lines.append(f"  {where}")
    elif not stages:
        lines.append(f"  no complete stage recorded in {where}")
    else:
        width = max(len(s) for s, _ in stages)
        lines += [f"  {stage:<{width}}  {_duration(sec):>12}" for stage, sec in stages]
        width = max(width, len("wall clock (two lanes side by side)"))
        lines.append(f"  {'total of the stages':<{width}}  {_duration(sum(s for _, s in stages)):>12}")
        lines.append(f"  {'wall clock (two lanes side by side)':<{width}}  {_duration(wall):>12}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    print(summary(argv[0] if argv else "results"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
