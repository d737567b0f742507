"""The task's constraints."""

COSTS = ("lane", "collision")
"""Constraint names; cost ``c`` is read from ``("next", "cost_<c>")``."""
