"""One workaround for a per-call cost in tensordict.

Every output a ``TensorDictModule`` writes goes through ``TensorDict.from_any``, which, for a
plain tensor, asks ``importlib.util.find_spec("pandas")`` before giving up; when pandas is not
installed that search walks ``sys.path`` and every import hook each time (0.06–0.2 ms, about
80 times per state PPO update: 3–5 % of it). Python answers ``find_spec`` from ``sys.modules``
first, so recording "not installed" there once makes the probe free, with the same answer.
"""

from __future__ import annotations

import importlib.util
import sys

PROBED = ("pandas",)
"""The optional modules tensordict probes for on every call."""


def settle_import_probes() -> list[str]:
    """Marks each module of :data:`PROBED` that is not installed as absent in ``sys.modules``
    (``find_spec`` then answers None at once; an import raises ImportError, as it would);
    returns the names marked. Installed modules are left alone."""
    marked = []
    for name in PROBED:
        if name not in sys.modules and importlib.util.find_spec(name) is None:
            sys.modules[name] = None  # type: ignore[assignment]
            marked.append(name)
    return marked


__all__ = ["PROBED", "settle_import_probes"]
