"""One-off trials whose results decided something (the docs hold each result): `python -m experiments.NAME`."""
