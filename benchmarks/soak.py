"""Soak: a collector stopped N times by SIGKILL, SIGTERM or SIGINT at random moments, then checked.

Each round starts `gym-fetch collect` on the same directory (so every round resumes the last),
waits a random time, sends a random one of the three signals, and records what the collector
reported saved. At the end: every reported demo must be in the dataset, `info` must call it valid,
and `replay --check` must find every demo exact. Prints a table of the rounds by signal and the
final checks.

    python -m benchmarks.soak --rounds 40 --out /tmp/soak
"""

from __future__ import annotations

import argparse
import collections
import pathlib
import random
import shutil
import signal
import subprocess
import sys
import time

from fetch.cli import main as cli
from fetch.dataset import open_dataset

SIGNALS = (signal.SIGKILL, signal.SIGTERM, signal.SIGINT)


def saved_names(text: str) -> set[str]:
    return {line.split()[1].rstrip(":") for line in text.splitlines() if line.startswith("saved demo_")}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=40, help="collector runs, each stopped by a signal (40)")
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("/tmp/fetch-soak"),
                        help="the dataset directory (emptied first; default /tmp/fetch-soak)")
    parser.add_argument("--env", default="Reach-v2", help="the task (Reach-v2: short demos, many saves)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the waits and signals (0)")
    args = parser.parse_args()
    shutil.rmtree(args.out, ignore_errors=True)
    rng = random.Random(args.seed)
    reported: set[str] = set()
    by_signal: dict[str, collections.Counter[str]] = collections.defaultdict(collections.Counter)
    start = time.perf_counter()
    samples: list[str] = []
    for _ in range(args.rounds):
        sig = rng.choice(SIGNALS)
        proc = subprocess.Popen([sys.executable, "-u", "-m", "fetch.cli", "collect", "--env", args.env,
                                 "--device", "expert", "--render", "none", "--episodes", "100000",
                                 "--out", str(args.out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        time.sleep(rng.uniform(0.2, 3.0))  # in the import, the resume, or among the saves
        proc.send_signal(sig)
        try:
            stdout, stderr = proc.communicate(timeout=120)
        except subprocess.TimeoutExpired:  # a collector that ignored its signal: count it, leave none behind
            proc.kill()
            stdout, stderr = proc.communicate()
            stderr += "\nsoak: no exit within 120 s of the signal; killed"
            by_signal[sig.name]["hung"] += 1
        reported |= saved_names(stdout)
        counts = by_signal[sig.name]
        counts["rounds"] += 1
        counts["saves reported"] += len(saved_names(stdout))
        counts["summary printed"] += " attempts, " in stdout
        counts[f"exit {proc.returncode}"] += 1
        counts["traceback"] += "Traceback" in stderr
        if ("Traceback" in stderr or proc.returncode == 1) and len(samples) < 3:
            samples.append(f"{sig.name}, exit {proc.returncode}:\n{stderr[-1200:]}")
    elapsed = time.perf_counter() - start
    print(f"{args.rounds} rounds on {args.env} in {elapsed:.0f} s; {len(reported)} demos reported saved\n")
    print("| signal | rounds | saves reported | summary printed | exit statuses | tracebacks | hung |")
    print("|---|---|---|---|---|---|---|")
    for name, c in sorted(by_signal.items()):
        exits = ", ".join(f"{k[5:]} x{v}" for k, v in sorted(c.items()) if k.startswith("exit "))
        print(f"| {name} | {c['rounds']} | {c['saves reported']} | {c['summary printed']} | {exits} | "
              f"{c['traceback']} | {c['hung']} |")
    with open_dataset(args.out) as ds:
        missing = sorted(reported - set(ds.demo_names))
        print(f"\ndataset: {len(ds.demo_names)} demos; reported but missing: {len(missing)} {missing[:5]}")
    for sample in samples:
        print(f"\nfirst failures, stderr:\n{sample}")
    info = cli(["info", str(args.out)])
    replay = cli(["replay", str(args.out), "--check"])
    print(f"info exit {info}, replay --check exit {replay}")
    hung = sum(c["hung"] for c in by_signal.values())
    return 0 if not missing and not hung and info == 0 and replay == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
