"""Runs variants against both servers, interleaved, and summarises them.

Ratios are only meaningful within one run on these shared machines
(docs/benchmarks.md), so every variant starts one bare relay and one ``rwt serve``
and alternates between them run by run (bare first on even runs, rwt first on
odd ones). A run that fails its correctness check marks the variant failed; it
is never silently dropped.
"""

from __future__ import annotations

import traceback
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from .scenarios.common import Context, Metrics, Run, Variant, summary
from .servers import Server, start_server

__all__ = ["VariantResult", "run_variant"]


@dataclass
class VariantResult:
    """Every run of one variant and its judgement."""

    variant: Variant
    runs: dict[str, list[Metrics]] = field(default_factory=dict)
    errors: list[str] = field(default_factory=list)
    shown: str = ""
    target: str = ""
    met: bool | None = None

    def medians(self) -> dict[str, dict[str, dict[str, float]]]:
        """kind -> metric -> {median, min, max}."""
        return {kind: summary(runs) for kind, runs in self.runs.items() if runs}


def _servers(variant: Variant, uvloop: bool, sources: Mapping[str, Path]) -> dict[str, Server]:
    """One server per kind; a kind named in ``sources`` is ``rwt`` run from that ``src``
    (its ``Server.kind`` stays ``rwt``: the load generator speaks rosbridge to it)."""
    servers: dict[str, Server] = {}
    try:
        for kind in variant.kinds:
            src = sources.get(kind)
            is_rwt = kind == "rwt" or src is not None
            extra = list(variant.server_args) if is_rwt else []
            servers[kind] = start_server(
                "rwt" if is_rwt else kind, uvloop=uvloop, extra=extra, src=src
            )
    except Exception:
        for server in servers.values():
            server.stop()
        raise
    return servers


def run_variant(
    variant: Variant,
    *,
    runs: int,
    scale: float,
    uvloop: bool,
    log: Callable[[str], None],
    context: Context | None = None,
    sources: Mapping[str, Path] | None = None,
) -> VariantResult:
    """Run ``variant`` ``runs`` times against each of its servers, interleaved.

    ``sources`` maps an extra kind (``base``) to the ``src`` of another checkout of rwt.
    """
    result = VariantResult(variant, {kind: [] for kind in variant.kinds})
    count = variant.runs or runs
    servers: dict[str, Server] = {}
    try:
        for index in range(count):
            if variant.fresh_server or not servers:
                _stop(servers)
                servers = _servers(variant, uvloop, sources or {})
            order: Sequence[str] = variant.kinds if index % 2 == 0 else variant.kinds[::-1]
            for kind in order:
                server = servers[kind]
                if not server.alive():
                    raise RuntimeError(f"the {kind} server died")
                try:
                    metrics = variant.run(Run(server, scale, context or {}))
                except Exception as exc:  # report, keep going with the other runs
                    detail = "".join(traceback.format_exception_only(exc)).strip()
                    result.errors.append(f"{kind} run {index + 1}: {detail}")
                    log(f"    {kind} run {index + 1} failed: {detail}")
                    continue
                result.runs[kind].append(metrics)
                log(f"    {kind} run {index + 1}: {_brief(metrics, variant.primary)}")
    finally:
        _stop(servers)
    return result


def _stop(servers: dict[str, Server]) -> None:
    for server in servers.values():
        server.stop()
    servers.clear()


def _brief(metrics: Metrics, primary: str) -> str:
    value = metrics.get(primary, float("nan"))
    gen = metrics.get("generator_cpu_pct")
    srv = metrics.get("server_cpu_pct")
    extra = "" if gen is None else f" (server {srv:.0f} % CPU, generator {gen:.0f} %)"
    return f"{primary}={value:,.4g}{extra}"
