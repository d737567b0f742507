"""The names an exported policy's ONNX graph and metadata use, shared by the export and the
pilot (no imports, so that the pilot on a robot needs no training stack)."""

INPUT, OUTPUT = "observation", "duty"
"""The graph's input and output."""
METADATA_PREFIX = "crllk."
"""Prefix of the metadata keys (``crllk.observation``, ``crllk.supersample``, ...)."""
OBSERVATIONS = ("pixels", "state")
"""What a policy may read (``crllk.observation``)."""
EXPORTABLE_ACTIONS = ("discrete", "continuous", "stoppable", "duckietown")
"""The action spaces whose policies export (``crllk.action``)."""

__all__ = ["EXPORTABLE_ACTIONS", "INPUT", "METADATA_PREFIX", "OBSERVATIONS", "OUTPUT"]
