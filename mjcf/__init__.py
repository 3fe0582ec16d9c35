"""The MJCF models, installed as the package data ``finrft.mjcf``."""
