"""Reproductions of the thesis' studies that are not part of the running system.

Nothing in the runtime packages imports from here (tests/test_layers.py checks it): a study may keep its own
representations (e.g. the chapter-3 separated solution) without constraining the runtime model format.
"""
