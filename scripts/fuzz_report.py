#!/usr/bin/env python3
"""docs/ci/fuzzing.md from scripts/fuzz's record (build-fuzz/record.tsv, this machine's runs)
and the record kept beside the page (docs/ci/fuzz-record.tsv, every machine's, which this
rewrites with the union): every target's runs, newest first, each stamped with the time it
finished, its commit, tree state and machine, and each target's longest clean run.

    scripts/fuzz_report.py RECORD.tsv PAGE.md        (scripts/fuzz --report)
"""

import sys
from pathlib import Path

FIELDS = ["date", "commit", "tree", "machine", "target", "seconds", "inputs", "findings", "exit"]
TARGETS = ["pcd", "ply", "mesh", "tar", "manifest", "gripper", "config", "calibration", "database", "log", "runs", "result", "mcap"]
SCHEDULE_S = 1800


def main(argv):
    if len(argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    record, page = Path(argv[1]), Path(argv[2])
    kept = page.with_name("fuzz-record.tsv")
    lines = []
    for source in (kept, record):
        if not source.exists():
            continue
        for n, line in enumerate(source.read_text().splitlines(), 1):
            if len(line.split("\t")) != len(FIELDS):
                print(f"fuzz_report: {source}, line {n}: {len(line.split(chr(9)))} fields, not {len(FIELDS)}",
                      file=sys.stderr)
                return 1
            if line not in lines:
                lines.append(line)
    if not lines:
        print(f"fuzz_report: no runs in {record} or {kept} (scripts/fuzz TARGET SECONDS records them)", file=sys.stderr)
        return 1
    lines.sort(key=lambda line: line.split("\t")[0])
    rows = [dict(zip(FIELDS, line.split("\t"))) for line in lines]
    rows.sort(key=lambda r: r["date"], reverse=True)
    out = ["# Fuzzing record", "",
           "Written by `scripts/fuzz --report` from the runs `scripts/fuzz` recorded; not by hand. The",
           f"schedule ([testing](../testing.md#hardening-fuzzed-readers)): before a release, every target for {SCHEDULE_S} s",
           "(`scripts/fuzz all 1800`, six and a half hours of one core), each finding kept as a corpus file and a test.", "",
           "## Every target's longest clean run", "",
           "| target | longest run without a finding | inputs | finished | commit |", "|---|---|---|---|---|"]
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
            "| finished (UTC) | commit | tree | machine | target | seconds | inputs | findings |",
            "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['date']} | `{r['commit']}` | {r['tree']} | {r['machine']} | `{r['target']}` | "
                   f"{r['seconds']} | {r['inputs']} | {r['findings']} |")
    for path, text in ((kept, "\n".join(lines) + "\n"), (page, "\n".join(out) + "\n")):
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(text)
        tmp.replace(path)
    print(f"fuzz_report: {page}: {len(rows)} runs")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
