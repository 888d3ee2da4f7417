"""The machine and the versions a measurement ran on: the line every benchmark prints above its table."""

from __future__ import annotations

import importlib.metadata
import os
import pathlib
import platform
import subprocess
import sys

PACKAGES = ("mujoco", "gymnasium", "numpy")
"""Named on every line, after python and fetch (distribution names, as pip spells them)."""


def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo (or platform's guess elsewhere)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def version(package: str) -> str:
    """The version of `package` (a distribution name) this process uses: the imported module's
    `__version__` where it is imported, else the installed distribution's, else "not installed".
    Nothing is imported here, so a benchmark decides its own import order (the GL backend)."""
    found = getattr(sys.modules.get(package.replace("-", "_")), "__version__", None)
    if isinstance(found, str):
        return found
    try:
        return importlib.metadata.version(package)
    except importlib.metadata.PackageNotFoundError:
        return "not installed"


def _git(where: pathlib.Path, *args: str) -> str:
    return subprocess.run(["git", "-C", str(where), *args], capture_output=True, text=True, check=True,
                          timeout=10).stdout.strip()


def _fetch_dir() -> pathlib.Path:
    """Where the fetch this process imports lives."""
    import fetch

    return pathlib.Path(fetch.__file__).resolve().parent


def fetch_commit() -> str:
    """The git commit of the fetch this process imported ("" where it is not a checkout), with ", with
    uncommitted changes" where its files differ from it."""
    where = _fetch_dir()
    try:
        commit = _git(where, "rev-parse", "--short", "HEAD")
        dirty = _git(where, "status", "--porcelain", "--", ".")
    except (OSError, subprocess.SubprocessError):
        return ""
    return commit + (", with uncommitted changes" if dirty else "")


def fetch_version() -> str:
    """fetch's version and where it was imported from, with the git commit when that is a checkout."""
    import fetch

    commit = fetch_commit()
    return f"{fetch.__version__} from {_fetch_dir()}" + (f" (git {commit})" if commit else "")


def machine(*extra: str) -> list[tuple[str, str]]:
    """(name, value) rows: CPU, cores, load average (1, 5, 15 min), OS, then the versions of python,
    fetch, `PACKAGES` and each distribution named in `extra` (e.g. "h5py", "torch")."""
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:
        usable = os.cpu_count() or 0
    try:
        load = " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        load = "unknown"
    return [
        ("CPU", cpu_model()),
        ("cores", f"{os.cpu_count()} ({usable} usable by this process)"),
        ("load average", load),
        ("OS", platform.platform()),
        ("python", platform.python_version()),
        ("fetch", fetch_version()),
        *((name, version(name)) for name in (*PACKAGES, *extra)),
    ]


def machine_line(*extra: str) -> str:
    """`machine(*extra)` as one line: `machine: CPU ..., cores ..., ..., numpy 2.4.6`."""
    return "machine: " + ", ".join(f"{name} {value}" for name, value in machine(*extra))


def machine_table(*extra: str) -> str:
    """`machine(*extra)` as a two-column markdown table."""
    return "\n".join(["| | |", "|---|---|", *(f"| {name} | {value} |" for name, value in machine(*extra))])
