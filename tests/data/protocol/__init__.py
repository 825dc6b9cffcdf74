"""Fake benchmark protocols (see data.py)."""
