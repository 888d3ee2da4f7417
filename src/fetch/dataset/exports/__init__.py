"""Exports of a dataset to other tools' formats: Minari, collect_fetch_demo.py's npz files, a LeRobotDataset;
`gym-fetch export` over one record per format (`exporters.py`)."""
