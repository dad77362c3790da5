"""Rendered sequences for tests (cached: each is rendered once per test session)."""

from simreal_nodes.synth.sequence import sequence  # noqa: F401
