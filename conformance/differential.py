"""The suite against the real rosbridge_suite (ROS 1) and `rwt serve --dialect ros1`, together.

    RWT_ROSBRIDGE_ROS1_URL=ws://127.0.0.1:19090 python conformance/differential.py
    python conformance/differential.py --peer-url ws://127.0.0.1:19090 --profile reference

The peer is a running rosbridge_suite 0.11.x (its ``rosbridge_websocket`` with
``rosapi``); how to start one is up to the machine, this script only connects. rwt
runs in this process on a free port, as ``rwt serve --dialect ros1`` would. Both
servers get the same cases in the same run, in the ROS 1 dialect, in each profile
asked for; the output is one markdown table per profile of the cases whose
outcomes differ, then the totals. Exit code 0 when the reference profile has no
failure on either server (or when no peer is given: it says it skips), 1 otherwise, 2 when
the peer cannot be reached.
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
PEER_NAME = "rosbridge_suite (ROS 1)"
RWT_NAME = "rwt serve --dialect ros1"


@dataclass(frozen=True)
class Differential:
    """The results of one profile on both servers."""

    profile: Profile
    peer: SuiteResult
    rwt: SuiteResult

    def differing(self) -> list[tuple[str, str, str, str]]:
        """``(case, peer outcome, rwt outcome, detail)`` for every case whose outcome differs."""
        rwt = {r.case.id: r for r in self.rwt.cases}
        rows = []
        for mine in self.peer.cases:
            theirs = rwt[mine.case.id]
            if mine.outcome is not theirs.outcome:
                detail = (mine.detail or theirs.detail).replace("|", "/")
                rows.append((mine.case.id, mine.outcome.value, theirs.outcome.value, detail))
        return rows


async def run(peer_url: str, profiles: list[Profile], timeout_s: float = 3.0) -> list[Differential]:
    """Run the suite in each profile against the peer and an in-process ROS 1 rwt.

    Raises:
        ConnectionError: the peer does not answer as a ROS 1 rosbridge server.
    """
    dialect, how = await detect_dialect(peer_url, timeout_s=timeout_s)
    if dialect is not Dialect.ROS1 or how.startswith("assumed"):
        raise ConnectionError(f"{peer_url} is not a ROS 1 rosbridge server: {how}")
    suite = load_suite()
    server = RosbridgeServer(Graph(TypeRegistry(GraphDialect.ROS1)), ServerConfig(port=0))
    results = []
    async with anyio.create_task_group() as tasks:
        rwt_url = await tasks.start(server.serve)
        for profile in profiles:
            options = {"profile": profile, "dialect": Dialect.ROS1, "expect_timeout_s": timeout_s}
            peer = await run_suite(suite, RunOptions(peer_url, **options))  # type: ignore[arg-type]
            rwt = await run_suite(suite, RunOptions(rwt_url, **options))  # type: ignore[arg-type]
            results.append(Differential(profile, peer, rwt))
        tasks.cancel_scope.cancel()
    return results


def render(results: list[Differential]) -> str:
    """The markdown report: totals, then the differing cases of each profile."""
    lines = [
        f"| profile | {PEER_NAME} | {RWT_NAME} |",
        "|---|---|---|",
    ]
    for result in results:
        lines.append(f"| {result.profile.value} | {_totals(result.peer)} | {_totals(result.rwt)} |")
    for result in results:
        rows = result.differing()
        lines += ["", f"Cases whose outcome differs, profile {result.profile.value}: {len(rows)}"]
        if rows:
            lines += [
                "",
                f"| case | {PEER_NAME} | {RWT_NAME} | first difference |",
                "|---|---|---|---|",
            ]
            lines += [f"| {c} | {p} | {r} | {d[:140]} |" for c, p, r, d in rows]
    return "\n".join(lines)


def _totals(result: SuiteResult) -> str:
    cases = {o: sum(1 for c in result.cases if c.outcome is o) for o in Outcome}
    return (
        f"{result.summary()} requirements; cases {cases[Outcome.PASSED]} passed,"
        f" {cases[Outcome.FAILED]} failed, {cases[Outcome.SKIPPED]} skipped"
    )


def main(argv: list[str] | None = None) -> int:
    """Parse options, run, print the report; the exit code of the module docstring."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--peer-url", default=os.environ.get(PEER_ENV), help=f"default ${PEER_ENV}")
    parser.add_argument(
        "--profile", action="append", choices=[p.value for p in Profile], help="default: both"
    )
    parser.add_argument("--timeout", type=float, default=3.0, help="seconds per expected frame")
    args = parser.parse_args(argv)
    if not args.peer_url:
        print(
            f"differential: skipped: no rosbridge_suite (ROS 1) to compare with;"
            f" set {PEER_ENV} or give --peer-url",
            file=sys.stderr,
        )
        return 0
    profiles = [Profile(p) for p in args.profile or [Profile.REFERENCE, Profile.STRICT]]
    try:
        results = anyio.run(run, args.peer_url, profiles, args.timeout)
    except ConnectionError as exc:
        print(f"differential: {exc}", file=sys.stderr)
        return 2
    print(render(results))
    reference = [r for r in results if r.profile is Profile.REFERENCE]
    return 0 if all(r.peer.ok and r.rwt.ok for r in reference) else 1


if __name__ == "__main__":
    sys.exit(main())
