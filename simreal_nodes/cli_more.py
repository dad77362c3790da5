"""CLI commands of the physics, synthesis and evaluation parts (registered by simreal_nodes.cli)."""

from __future__ import annotations


def add_commands(sub) -> None:
    """Filled in as the parts land: build-model, make-bag, demo, eval-trajectory, eval-tracking."""
