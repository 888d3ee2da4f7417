"""Write tests/slow.txt, the tests the `slow` marker selects, from a timed run of the whole suite.

    .venv/bin/python -m pytest -q --durations=0 > durations.log
    python scripts/mark_slow.py durations.log [--over 0.5]

A test is slow when its setup, call and teardown took `--over` seconds or more together (a module's
shared fixture counts in the first test that uses it). `pytest -m "not slow"` then runs the rest:
the fast subset a developer runs between edits; the full suite stays what CI runs.
"""

from __future__ import annotations

import argparse
import collections
import pathlib
import re

LINE = re.compile(r"^([0-9.]+)s (?:call|setup|teardown)\s+(.+?)\s*$")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log", help="the output of pytest --durations=0")
    parser.add_argument("--over", type=float, default=0.5, help="seconds that make a test slow (default 0.5)")
    args = parser.parse_args()
    seconds: collections.Counter[str] = collections.Counter()
    for line in pathlib.Path(args.log).read_text().splitlines():
        if match := LINE.match(line):
            seconds[match.group(2)] += float(match.group(1))
    slow = sorted(test for test, spent in seconds.items() if spent >= args.over)
    out = pathlib.Path(__file__).resolve().parents[1] / "tests" / "slow.txt"
    out.write_text("".join(f"{test}\n" for test in slow))
    fast = sum(spent for spent in seconds.values() if spent < args.over)
    print(f"{len(slow)} slow tests written to {out}; the rest took {fast:.0f} s in that run")


if __name__ == "__main__":
    main()
