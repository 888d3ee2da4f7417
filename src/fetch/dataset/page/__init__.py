"""`gym-fetch view`'s static web page of a dataset: the demos' videos, series and flags in one HTML file."""
