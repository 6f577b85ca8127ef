"""The suite against the real rosbridge_suite and `rwt serve` in the same dialect, together.

    RWT_ROSBRIDGE_ROS1_URL=ws://127.0.0.1:19090 python conformance/differential.py
    python conformance/differential.py --peer-url ws://127.0.0.1:19090 --profile reference
    RWT_ROSBRIDGE_ROS2_URL=ws://127.0.0.1:9590 python conformance/differential.py --dialect ros2

The peer is a running rosbridge_suite, 0.11.x for ROS 1 or 2.1.0 for ROS 2 (its
``rosbridge_websocket`` with ``rosapi``); how to start one is up to the machine, this
script only connects. rwt runs in this process on a free port, as ``rwt serve
--dialect ros1`` (or ``ros2``) would. Both servers get the same cases in the same
run, in the peer's dialect, in each profile asked for; the output is one markdown
table per profile of the cases whose outcomes differ, then the totals. Exit code 0
when the reference profile has no failure on either server (or when no peer is given:
it says it skips), 1 otherwise, 2 when the peer cannot be reached. Where the peer
breaks the spec, the reference profile accepts its recorded way
(docs/reference-behaviour.md §12, ``Step.defect``). Each server is judged by its own
spec version (docs/conformance.md, "Spec versions": the peers are unversioned, rwt
answers 2.1.0); a case one of them skips for its version is not a difference. Run
the reference profile first: the strict one can stall a ROS 2 peer's rosapi (REF §12.9).
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import dataclass

import anyio

from rwt_conformance import Outcome, Profile, RunOptions, SuiteResult, load_suite, run_suite
from rwt_conformance.detect import detect_dialect
from rwt_conformance.model import Dialect
from rwt_graph.graph import Graph
from rwt_graph.types.names import Dialect as GraphDialect
from rwt_graph.types.registry import TypeRegistry
from rwt_transports.server import RosbridgeServer, ServerConfig

PEER_ENV = "RWT_ROSBRIDGE_ROS1_URL"
PEER2_ENV = "RWT_ROSBRIDGE_ROS2_URL"
PEER_ENVS = {Dialect.ROS1: PEER_ENV, Dialect.ROS2: PEER2_ENV}
"""The variable giving the peer of each dialect."""
_VERSIONS = {Dialect.ROS1: "0.11.x", Dialect.ROS2: "2.1.0"}


def peer_name(dialect: Dialect) -> str:
    """How the report names the peer: ``rosbridge_suite (ROS 1)``."""
    return f"rosbridge_suite (ROS {dialect.value[-1]})"


def rwt_name(dialect: Dialect) -> str:
    """How the report names rwt: ``rwt serve --dialect ros1``."""
    return f"rwt serve --dialect {dialect.value}"


@dataclass(frozen=True)
class Differential:
    """The results of one profile on both servers."""

    profile: Profile
    peer: SuiteResult
    rwt: SuiteResult
    dialect: Dialect = Dialect.ROS1

    def differing(self) -> list[tuple[str, str, str, str]]:
        """``(case, peer outcome, rwt outcome, detail)`` for every case whose outcome differs.

        A case either server skips for its spec version (``CaseResult.off_version``)
        is left out: the two are judged by different versions there.
        """
        rwt = {r.case.id: r for r in self.rwt.cases}
        rows = []
        for mine in self.peer.cases:
            theirs = rwt[mine.case.id]
            if mine.off_version or theirs.off_version:
                continue
            if mine.outcome is not theirs.outcome:
                detail = (mine.detail or theirs.detail).replace("|", "/")
                rows.append((mine.case.id, mine.outcome.value, theirs.outcome.value, detail))
        return rows


async def run(
    peer_url: str,
    profiles: list[Profile],
    timeout_s: float = 3.0,
    dialect: Dialect = Dialect.ROS1,
) -> list[Differential]:
    """Run the suite in each profile against the peer and an in-process rwt of ``dialect``.

    Raises:
        ConnectionError: the peer does not answer as a rosbridge server of ``dialect``.
    """
    found, how = await detect_dialect(peer_url, timeout_s=timeout_s)
    if found is not dialect or how.startswith("assumed"):
        edition = dialect.value[-1]
        raise ConnectionError(f"{peer_url} is not a ROS {edition} rosbridge server: {how}")
    suite = load_suite()
    graph_dialect = GraphDialect.ROS1 if dialect is Dialect.ROS1 else GraphDialect.ROS2
    server = RosbridgeServer(Graph(TypeRegistry(graph_dialect)), ServerConfig(port=0))
    results = []
    async with anyio.create_task_group() as tasks:
        rwt_url = await tasks.start(server.serve)
        for profile in profiles:
            options = {"profile": profile, "dialect": dialect, "expect_timeout_s": timeout_s}
            peer = await run_suite(suite, RunOptions(peer_url, **options))  # type: ignore[arg-type]
            rwt = await run_suite(suite, RunOptions(rwt_url, **options))  # type: ignore[arg-type]
            results.append(Differential(profile, peer, rwt, dialect))
        tasks.cancel_scope.cancel()
    return results


def render(results: list[Differential]) -> str:
    """The markdown report: totals, then the differing cases of each profile."""
    dialect = results[0].dialect if results else Dialect.ROS1
    lines = [
        f"| profile | {peer_name(dialect)} | {rwt_name(dialect)} |",
        "|---|---|---|",
    ]
    for result in results:
        lines.append(f"| {result.profile.value} | {_totals(result.peer)} | {_totals(result.rwt)} |")
    if results:
        lines += [
            "",
            f"{peer_name(dialect)}: {_spec(results[0].peer)}; {rwt_name(dialect)}:"
            f" {_spec(results[0].rwt)}",
        ]
    for result in results:
        rows = result.differing()
        lines += ["", f"Cases whose outcome differs, profile {result.profile.value}: {len(rows)}"]
        if rows:
            lines += [
                "",
                f"| case | {peer_name(dialect)} | {rwt_name(dialect)} | first difference |",
                "|---|---|---|---|",
            ]
            lines += [f"| {c} | {p} | {r} | {d[:140]} |" for c, p, r, d in rows]
    return "\n".join(lines)


def _spec(result: SuiteResult) -> str:
    return "spec version unknown" if result.spec is None else result.spec.describe()


def _totals(result: SuiteResult) -> str:
    cases = {o: sum(1 for c in result.cases if c.outcome is o) for o in Outcome}
    stopped = "" if result.verdict is None else f"; stopped: {result.verdict}"
    return (
        f"{result.summary()} requirements; cases {cases[Outcome.PASSED]} passed,"
        f" {cases[Outcome.FAILED]} failed, {cases[Outcome.SKIPPED]} skipped{stopped}"
    )


def main(argv: list[str] | None = None) -> int:
    """Parse options, run, print the report; the exit code of the module docstring."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--dialect", choices=[d.value for d in Dialect], default="ros1", help="the peer's"
    )
    parser.add_argument("--peer-url", help=f"default ${PEER_ENV} (ros1) or ${PEER2_ENV} (ros2)")
    parser.add_argument(
        "--profile", action="append", choices=[p.value for p in Profile], help="default: both"
    )
    parser.add_argument("--timeout", type=float, default=3.0, help="seconds per expected frame")
    args = parser.parse_args(argv)
    dialect = Dialect(args.dialect)
    peer_url = args.peer_url or os.environ.get(PEER_ENVS[dialect])
    if not peer_url:
        print(
            f"differential: skipped: no {peer_name(dialect)} ({_VERSIONS[dialect]}) to compare"
            f" with; set {PEER_ENVS[dialect]} or give --peer-url",
            file=sys.stderr,
        )
        return 0
    profiles = [Profile(p) for p in args.profile or [Profile.REFERENCE, Profile.STRICT]]
    try:
        results = anyio.run(run, peer_url, profiles, args.timeout, dialect)
    except ConnectionError as exc:
        print(f"differential: {exc}", file=sys.stderr)
        return 2
    print(render(results))
    reference = [r for r in results if r.profile is Profile.REFERENCE]
    return 0 if all(r.peer.ok and r.rwt.ok for r in reference) else 1


if __name__ == "__main__":
    sys.exit(main())
