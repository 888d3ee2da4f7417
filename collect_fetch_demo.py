#!/usr/bin/env python
"""The project's original demonstration collector, kept for its users: every flag of the original script, with
its meaning, runs `gym-fetch collect` (see `gym-fetch collect --help`)."""

from __future__ import annotations

import sys

from fetch.collect import collect_main

if __name__ == "__main__":
    raise SystemExit(collect_main(sys.argv[1:], prog="collect_fetch_demo.py"))
