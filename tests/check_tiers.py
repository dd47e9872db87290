#!/usr/bin/env python3
"""Every test of the build folder argv[1] has exactly one tier label of tests/tiers.cmake and a
timeout (ctest --show-only=json-v1). Run by ctest as tiers/every_test_labelled."""
import json
import subprocess
import sys

TIERS = {"unit", "integration", "slow", "python", "package"}

build = sys.argv[1]
listing = json.loads(subprocess.run(["ctest", "--test-dir", build, "--show-only=json-v1"],
                                    check=True, capture_output=True, text=True).stdout)
bad = []
for test in listing["tests"]:
    props = {p["name"]: p["value"] for p in test.get("properties", [])}
    tiers = [label for label in props.get("LABELS", []) if label in TIERS]
    timeout = props.get("TIMEOUT", 0)
    if len(tiers) != 1 or not timeout > 0:
        bad.append(f"{test['name']}: tier labels {tiers}, timeout {timeout or 'none'}")
for line in bad:
    print(line, file=sys.stderr)
if bad:
    sys.exit(f"{len(bad)} of {len(listing['tests'])} tests without exactly one tier or a timeout (tests/tiers.cmake)")
print(f"tiers: ok, {len(listing['tests'])} tests, each with one tier and a timeout")
