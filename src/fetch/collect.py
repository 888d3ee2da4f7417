"""`python -m fetch.collect ARGS`, the same as `gym-fetch collect ARGS`; and `collect_main`, the original script's
entry (`collect_fetch_demo.py`). Both live in the command layer, `fetch.commands.collect`."""

from __future__ import annotations

from fetch.commands.collect import collect_main, main

__all__ = ["collect_main", "main"]

if __name__ == "__main__":
    raise SystemExit(main())
