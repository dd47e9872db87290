#!/usr/bin/env python3
"""docs/ci/fuzzing.md from scripts/fuzz's record (build-fuzz/record.tsv): every target's runs,
newest first, each stamped with its date, commit, tree state and machine, and the schedule's
check: whether each target has had a run of at least 1800 s without a finding on the newest
commit fuzzed.

    scripts/fuzz_report.py RECORD.tsv PAGE.md        (scripts/fuzz --report)
"""

import sys
from pathlib import Path

FIELDS = ["date", "commit", "tree", "machine", "target", "seconds", "inputs", "findings", "exit"]
TARGETS = ["pcd", "ply", "mesh", "tar", "manifest", "gripper", "config", "database", "log", "runs", "result", "mcap"]
SCHEDULE_S = 1800


def main(argv):
    if len(argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    record, page = Path(argv[1]), Path(argv[2])
    if not record.exists():
        print(f"fuzz_report: no record {record} (scripts/fuzz TARGET SECONDS writes it)", file=sys.stderr)
        return 1
    rows = []
    for n, line in enumerate(record.read_text().splitlines(), 1):
        cells = line.split("\t")
        if len(cells) != len(FIELDS):
            print(f"fuzz_report: {record}, line {n}: {len(cells)} fields, not {len(FIELDS)}", file=sys.stderr)
            return 1
        rows.append(dict(zip(FIELDS, cells)))
    rows.sort(key=lambda r: r["date"], reverse=True)
    out = ["# Fuzzing record", "",
           "Written by `scripts/fuzz --report` from the runs `scripts/fuzz` recorded; not by hand. The",
           f"schedule ([testing](../testing.md#hardening-fuzzed-readers)): before a release, every target for {SCHEDULE_S} s",
           "(`scripts/fuzz all 1800`, six hours of one core), each finding kept as a corpus file and a test.", "",
           "## Every target's longest clean run", "",
           "| target | longest run without a finding | inputs | date | commit |", "|---|---|---|---|---|"]
    for t in TARGETS:
        clean = [r for r in rows if r["target"] == t and r["findings"] == "0" and r["exit"] == "0"]
        if not clean:
            out.append(f"| `{t}` | none recorded | | | |")
            continue
        best = max(clean, key=lambda r: int(r["seconds"]))
        mark = "" if int(best["seconds"]) >= SCHEDULE_S else f" (short of {SCHEDULE_S} s)"
        out.append(f"| `{t}` | {best['seconds']} s{mark} | {best['inputs']} | {best['date'][:10]} | "
                   f"`{best['commit']}`{'' if best['tree'] == 'clean' else ' (tree not clean)'} |")
    out += ["", "## Every run, newest first", "",
            "| date (UTC) | commit | tree | machine | target | seconds | inputs | findings |",
            "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['date']} | `{r['commit']}` | {r['tree']} | {r['machine']} | `{r['target']}` | "
                   f"{r['seconds']} | {r['inputs']} | {r['findings']} |")
    tmp = page.with_suffix(".md.tmp")
    tmp.write_text("\n".join(out) + "\n")
    tmp.replace(page)
    print(f"fuzz_report: {page}: {len(rows)} runs")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
