"""Recorded data sets (loaders only; the project ships no data)."""

from coloc_env.data.mrclam import MrclamData, load, load_cached, resolve_data_path

__all__ = ["MrclamData", "load", "load_cached", "resolve_data_path"]
