#!/usr/bin/env python3
"""scripts/results: its checks refuse what they should, on a copy of the tree's registry and pages.

  test_results.py SOURCE_DIR       (ctest: scripts/results_check_refuses)
Each case edits a fresh copy (registry, README, docs/) and expects `scripts/results check` or
`--list` to fail naming the file and the field, or to pass when nothing is wrong."""
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

src = Path(sys.argv[1]).resolve()
script = src / "scripts/results"
failures = []
cases = 0


def tree():
    d = Path(tempfile.mkdtemp(prefix="ts-results-"))
    for f in ["README.md", "datasets/dev45.tsv"]:
        (d / f).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(src / f, d / f)
    shutil.copytree(src / "experiments/studies", d / "experiments/studies")
    shutil.copytree(src / "docs", d / "docs")
    return d


def expect(name, edit, args, code, needle):
    global cases
    cases += 1
    d = tree()
    try:
        edit(d)
        p = subprocess.run([sys.executable, script, "--root", d, *args], capture_output=True, text=True)
        if p.returncode != code or needle not in p.stderr + p.stdout:
            failures.append(f"{name}: exit {p.returncode} (want {code}), output:\n{p.stderr}{p.stdout}")
    finally:
        shutil.rmtree(d)


def append(path, text):
    return lambda d: (d / path).open("a").write(text)


def page(name, files=("README.md", "result.json", "stamp.json")):
    def make(d):
        shutil.rmtree(d / "docs/results" / name, ignore_errors=True)
        (d / "docs/results" / name).mkdir(parents=True)
        for f in files:
            (d / "docs/results" / name / f).write_text(
                '{"commit": "x", "dirty": false, "machine": "m", "threads": 2, "allocator": "a", "date": "d"}'
                if f == "stamp.json" else "{}")
    return make


expect("the tree as it is", lambda d: None, ["check"], 0, "")
expect("a page of no study", page("study99_nothing"), ["check"], 1, "study99_nothing: a page of no study")
expect("a page without its stamp", page("demo", ("README.md", "result.json")), ["check"], 1, "no stamp.json")
expect("a link to no study's page", append("docs/testing.md", "\nsee docs/results/study77/README.md\n"),
       ["check"], 1, "docs/testing.md:")
expect("a figure the report does not write",
       lambda d: (d / "experiments/studies/registry.toml").write_text(
           (d / "experiments/studies/registry.toml").read_text().replace(
               '"recognition_rate", "position_error_m_median", "time_s_median"]',
               '"recognition_rate", "position_error_mm", "time_s_median"]', 1)),
       ["--list"], 1, "position_error_mm is not a per-step key")
expect("a tier over its budget", append("experiments/studies/registry.toml", '''
[studies.long_one]
title = "t"
tier = "quick"
kind = "bench"
database = "dev45"
program = "bench/x"
minutes = 30
'''), ["--list"], 1, "the quick tier expects")
expect("a commit hash in the README", append("README.md", "\nmeasured at 1103ea2 on a laptop\n"),
       ["check"], 1, "1103ea2 looks like a commit hash")
expect("an unknown study", lambda d: None, ["study99"], 1, "no study 'study99'")
expect("a study's unknown key", append("experiments/studies/registry.toml", '\n[studies.x]\ntitle = "t"\ncolour = 1\n'),
       ["--list"], 1, "studies.x: unknown key colour")
expect("a recipe's prepare that is not a list of commands",
       append("experiments/studies/registry.toml", '\n[databases.bad]\ncommand = ["db", "build", "--out", "{out}"]\n'
              'prepare = ["catalogue", "--count", "2"]\n'),
       ["--list"], 1, "databases.bad.prepare: a list of commands")
expect("a recipe's unknown key",
       append("experiments/studies/registry.toml", '\n[databases.bad]\ncommand = ["db", "build", "--out", "{out}"]\n'
              'inputz = ["datasets/dev45.tsv"]\n'),
       ["--list"], 1, "databases.bad: unknown key inputz")

expect("render of no study", lambda d: None, ["render", "study99"], 1, "render: name studies of the registry")
expect("render of a study without a page", page("study4_db5_full", ("stamp.json",)), ["render", "study4_db5_full"],
       1, "no complete page to render")


def render_case():
    """`render` rewrites a page from what it holds: the same bytes when the registry did not change;
    a figure added to the registry appears as a column, the stamp and the report text unchanged."""
    global cases
    cases += 1
    d = tree()
    try:
        pages = sorted(p.name for p in (d / "docs/results").iterdir() if (p / "stamp.json").exists())
        before = {n: (d / "docs/results" / n / "README.md").read_text() for n in pages}
        p = subprocess.run([sys.executable, script, "--root", d, "render", *pages], capture_output=True, text=True)
        changed = [n for n in pages if (d / "docs/results" / n / "README.md").read_text() != before[n]]
        if p.returncode != 0 or changed:
            failures.append(f"render as it is: exit {p.returncode}, changed {changed}:\n{p.stderr}")
        registry = d / "experiments/studies/registry.toml"
        text = registry.read_text()
        anchor = ('figures = ["recognition_rate", "position_error_m_median", '
                  '"symmetric_orientation_error_deg_median", "time_s_median"]')
        at = text.find("[studies.demo]")
        wider = anchor.replace('"time_s_median"', '"time_s_median", "mssd_m_median"')
        registry.write_text(text[:at] + text[at:].replace(anchor, wider, 1))
        p = subprocess.run([sys.executable, script, "--root", d, "render", "demo"], capture_output=True, text=True)
        after = (d / "docs/results/demo/README.md").read_text()
        def stamp(t):
            return t.split("## Stamp")[1].split("Study file")[0]

        def report(t):
            return t.split("## The report")[1]
        if p.returncode != 0 or "| mssd_m_median |" not in after or stamp(before["demo"]) != stamp(after) or \
                report(before["demo"]) != report(after):
            failures.append(f"render with a figure added: exit {p.returncode}\n{p.stderr}")
    finally:
        shutil.rmtree(d)


render_case()


def load_case():
    """A stamp's load record: a quiet machine's mean load is stated; one above the study's own
    threads marks its times as slowed; a stamp without one says nothing of it."""
    global cases
    import json
    for mean_sum, shared in ((8.4, False), (14.0, True), (None, False)):
        cases += 1
        d = tree()
        try:
            path = d / "docs/results/demo/stamp.json"
            st = json.loads(path.read_text())
            st["threads"] = 2
            st.pop("load", None)
            if mean_sum is not None:
                st["load"] = {"samples": 4, "sum": mean_sum, "max": 4.2, "complete": True}
            path.write_text(json.dumps(st))
            p = subprocess.run([sys.executable, script, "--root", d, "render", "demo"], capture_output=True, text=True)
            text = (d / "docs/results/demo/README.md").read_text()
            q = subprocess.run([sys.executable, script, "--root", d, "index"], capture_output=True, text=True)
            row = [r for r in (d / "docs/results/index.md").read_text().splitlines() if r.startswith("| [demo]")]
            if q.returncode != 0 or len(row) != 1 or ("shared machine" in row[0]) != shared:
                failures.append(f"load stamp {mean_sum} in the index: exit {q.returncode}, row {row}\n{q.stderr}")
            want = None if mean_sum is None else f"load average {mean_sum / 4:.1f} on average, 4.2 at most"
            ok = p.returncode == 0 and (("machine load" in text) == (want is not None)) and \
                (want is None or want in text) and (("the machine was shared" in text) == shared)
            if not ok:
                failures.append(f"load stamp {mean_sum}: exit {p.returncode}\n{p.stderr}")
        finally:
            shutil.rmtree(d)


load_case()


FAKE_TOUCHSTONE = r"""#!/usr/bin/env bash
# A stand-in for touchstone: db build and experiment write their --out, report prints a result.
out=""; prev=""
for a in "$@"; do [ "$prev" = "--out" ] && out="$a"; prev="$a"; done
case "$1 $2" in
  "db build") : > "$out" ;;
  experiment*) sleep 0.2; [ -n "${FAKE_FAIL:-}" ] && exit 3; : > "$out" ;;
  report*)
    if [ "$3" = "--json" ]; then
      echo '{"per_step": [{"step": 1, "runs": 1, "recognition_rate": 0.5}, {"step": 20, "runs": 1, "recognition_rate": 1.0}]}'
    else
      echo "the report"
    fi ;;
esac
"""


def run_case():
    """A study run end to end with a stand-in touchstone: the stamp holds the load it ran under and
    result.json does not; a failed run keeps its load and time in the ledger, and the rerun that
    resumes it adds to them."""
    global cases
    import json
    cases += 1
    d = tree()
    try:
        git = ["git", "-C", str(d), "-c", "user.email=t@t", "-c", "user.name=t"]
        for folder in ("engine", "io"):   # sources the database's key reads
            (d / folder).mkdir()
            (d / folder / "source.cpp").write_text("// a source\n")
        subprocess.run(git + ["init", "-q"], check=True)
        subprocess.run(git + ["add", "-A"], check=True)
        subprocess.run(git + ["commit", "-q", "-m", "t"], check=True)
        build = d / "fakebuild"
        build.mkdir()
        (build / "touchstone").write_text(FAKE_TOUCHSTONE)
        (build / "touchstone").chmod(0o755)
        (build / "CMakeCache.txt").write_text("TS_SCALABLE_MALLOC:BOOL=ON\n")
        cmd = [sys.executable, script, "--root", d, "--build", build, "--no-build", "demo"]
        import os
        failed = subprocess.run(cmd, capture_output=True, text=True, env=dict(os.environ, FAKE_FAIL="1"))
        ledgers = list((build / "results/runs/demo").glob("*/seconds.json"))
        kept = json.loads(ledgers[0].read_text()) if len(ledgers) == 1 else {}
        if failed.returncode == 0 or kept.get("load", {}).get("samples", 0) < 1 or kept.get("seconds") is None:
            failures.append(f"a failed run keeps its load and time: exit {failed.returncode}, ledger {kept}\n{failed.stderr}")
        p = subprocess.run(cmd, capture_output=True, text=True)
        page = d / "docs/results/demo"
        result = json.loads((page / "result.json").read_text()) if p.returncode == 0 else {}
        stamp = json.loads((page / "stamp.json").read_text()) if p.returncode == 0 else {}
        load = stamp.get("load", {})
        if p.returncode != 0 or "_load" in result or load.get("samples", 0) < 2 or load.get("complete") is not True or \
                "machine load while it ran" not in (page / "README.md").read_text():
            failures.append(f"the rerun's page: exit {p.returncode}, stamp {stamp}, result keys {list(result)}\n{p.stderr}")
    finally:
        shutil.rmtree(d)


def load_script():
    import importlib.machinery
    import importlib.util
    loader = importlib.machinery.SourceFileLoader("results_script", str(script))
    module = importlib.util.module_from_spec(importlib.util.spec_from_loader("results_script", loader))
    loader.exec_module(module)
    return module


def db_sources_case():
    """The database key's sources: every project file `touchstone db build` and `touchstone catalogue`
    compile from (their include closure, each header's .cpp followed) is among DB_SOURCES and not
    excluded; and the key moves with a builder source, not with a recognizer source."""
    global cases
    import os
    m = load_script()
    listed = m.db_sources(src, False)   # what git lists of DB_SOURCES (a path or a folder each)
    covered = lambda f: f"\t{f}\n" in listed + "\n"
    cases += 1
    cxx = os.environ.get("CXX", "c++")
    todo, seen, missing = ["experiments/cli/cmd_db.cpp", "experiments/cli/cmd_catalogue.cpp"], set(), set()
    while todo:
        f = todo.pop()
        if f in seen:
            continue
        seen.add(f)
        p = subprocess.run([cxx, "-std=c++20", "-I.", "-isystem", "/usr/include/eigen3", "-MM", f], cwd=src,
                           capture_output=True, text=True)
        if p.returncode != 0:
            failures.append(f"{cxx} -MM {f} failed:\n{p.stderr[-2000:]}")
            continue
        for dep in p.stdout.replace("\\\n", " ").split()[1:]:
            if not dep.startswith(("engine/", "io/", "datasets/", "experiments/")):
                continue
            if not covered(dep):
                missing.add(dep)
            cpp = dep.rsplit(".", 1)[0] + ".cpp"
            if dep.endswith(".hpp") and (src / cpp).is_file():
                todo.append(cpp)
    if missing or len(seen) < 20:
        failures.append(f"database sources: {len(seen)} files followed; not in the key: {sorted(missing)}")
    cases += 1
    d = Path(tempfile.mkdtemp(prefix="ts-dbkey-"))
    try:
        git = ["git", "-C", str(d), "-c", "user.email=t@t", "-c", "user.name=t"]
        files = {"engine/geometry/a.cpp": "1", "engine/recognition/b.cpp": "1", "datasets/scene.cpp": "1"}
        for f, text in files.items():
            (d / f).parent.mkdir(parents=True, exist_ok=True)
            (d / f).write_text(text)
        subprocess.run(git + ["init", "-q"], check=True)
        keys = []
        for f in [None, "engine/recognition/b.cpp", "datasets/scene.cpp", "engine/geometry/a.cpp"]:
            if f:
                (d / f).write_text("2")
                dirty = m.db_sources(d, True)
                subprocess.run(git + ["commit", "-qam", "t"], check=True)
                keys.append((dirty, m.db_sources(d, False)))
            else:
                subprocess.run(git + ["add", "-A"], check=True)
                subprocess.run(git + ["commit", "-q", "-m", "t"], check=True)
                keys.append((None, m.db_sources(d, False)))
        base = keys[0][1]
        if not (keys[1] == (base, base) and keys[2] == (base, base) and keys[3][0] != base and keys[3][1] != base
                and "engine/geometry/a.cpp" in base):
            failures.append(f"the database key: {keys}")
    finally:
        shutil.rmtree(d)


run_case()
db_sources_case()

for f in failures:
    print(f"FAIL {f}", file=sys.stderr)
print(f"{cases - len(failures)} of {cases} cases as expected")
sys.exit(1 if failures else 0)
