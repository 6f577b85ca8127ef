"""Reproductions of the Robot Web Tools paper's figures (``python -m benchmarks.paper``).

Each module (tf, video, depthcloud, png) has ``run(quick: bool) -> list[dict]``
returning rows with ``figure``, ``metric``, ``paper``, ``ours``, ``unit`` and ``note``.
"""
