"""Stand-ins for what tests and benchmarks lack: a pad (`vpad`), a person at it (`operators`), /proc (`procs`)."""
