"""Fake-data generators of the tests, one package per kind (``tests/data/<name>/data.py``)."""
