"""What builds the package's data files (src/fetch/assets); run one as `python -m tools.NAME` from the repo root."""
