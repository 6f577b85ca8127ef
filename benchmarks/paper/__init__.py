"""The Robot Web Tools paper's measurements, reproduced side by side with rwt's.

Each module in ``MODULES`` that exists exposes ``run(quick: bool) -> list[Row]``;
``python -m benchmarks.paper [--quick]`` runs them all, prints one table, writes
``benchmarks/results/paper.json`` and rewrites the marked section of
``benchmarks/README.md`` (``--quick``: copies under ``benchmarks/results/quick/``).
A row is a dict with the keys of ``ROW_KEYS``: ``figure`` ("Fig. 3", "Table I"...),
``metric``, ``paper`` (the paper's number, None where it gives none), ``ours``,
``unit`` and ``note``.
"""

from __future__ import annotations

__all__ = ["FIGURES", "MODULES", "ROW_KEYS", "Row"]

#: The benchmark modules, in the paper's order (IV.A-IV.D).
MODULES = ("tf", "video", "depthcloud", "png")
#: The figure or table each module's rows belong to (``--only`` keeps the others' rows).
FIGURES = {"tf": "Fig. 3", "video": "Table I", "depthcloud": "Table II", "png": "Table III"}
ROW_KEYS = ("figure", "metric", "paper", "ours", "unit", "note")

Row = dict[str, object]
