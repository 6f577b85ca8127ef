"""Services of the in-memory graph (spec 3.3.6-3.3.9, D4, D15-D17, D25).

A service is provided either by a client (its session receives ``call_service``
requests with ids ``service_request:<name>:<n>``, REF §2.7) or by Python code in
this process (a sync or async callable). A service belongs to its provider:
only it answers, it goes when the provider unadvertises or leaves, and a newer
advertisement replaces it (D15). Every pending caller hears back: with the
response, or with ``result: false`` and a reason (D4).
"""

from __future__ import annotations

import inspect
import itertools
import logging
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING

from rwt_protocol.errors import FieldError, GraphError, RwtError, UnknownNameError
from rwt_protocol.levels import StatusLevel
from rwt_protocol.names import resolve_name
from rwt_protocol.ops import CallService
from rwt_protocol.ports import ClientId, ServiceProvider, ServiceReply

from .calls import ProviderTable, Spawner, convert_args, guarded
from .ratelog import EpisodeLog

if TYPE_CHECKING:
    from .clock import Clock
    from .types import ServiceType, TypeRegistry

__all__ = [
    "Amend",
    "CallerServiceHandler",
    "DiscoveryWait",
    "LocalServiceHandler",
    "PendingCall",
    "ServiceEntry",
    "Services",
]

logger = logging.getLogger("rwt.graph")
_episodes = EpisodeLog(logger)  # a peer can trigger these per message

Message = dict[str, object]
LocalServiceHandler = Callable[[Message], Message | Awaitable[Message]]
"""An in-process service: takes the request dict, returns (or awaits) the response dict."""
CallerServiceHandler = Callable[[ClientId, Message], Message | Awaitable[Message]]
"""An in-process service that is also told who calls (rosapi filters names per client)."""
Amend = Callable[[Message], Message]
"""Rewrites a checked response of an in-process service before it is sent."""
DiscoveryWait = Callable[[Callable[[], None]], "Callable[[], None] | None"]
"""A link's offer to wait for a service its discovery may not have found yet.

Called with ``expire`` when a call names a service nobody offers: returns None
when the link has nothing to wait for, else a function cancelling the wait; the
link calls ``expire`` (on the event loop) when its wait is over. ``Services``
holds the call meanwhile and starts it if the service comes; a call with a
``timeout`` of its own is held until that timeout instead, whatever the link's
wait (docs/ros2.md)."""


def _kept() -> None:
    """A link's wait ended for a call held until its own timeout: it waits on."""


@dataclass(eq=False)
class _Parked:
    """A call waiting for its service to be discovered (the arguments of ``Services.call``)."""

    call: PendingCall
    service: str
    args: object
    type_name: str | None
    path: str
    cancels: list[Callable[[], None]]
    waits: int = 0  # links still waiting for the service


class PendingCall:
    """One call in flight; resolves once, then forgets its caller."""

    def __init__(self, caller: ClientId, reply: ServiceReply) -> None:
        self.caller = caller
        self._reply: ServiceReply | None = reply
        self.cancel_job: Callable[[], None] | None = None
        self.on_settled: Callable[[], None] | None = None  # its table forgets it

    @property
    def done(self) -> bool:
        """Whether the caller has been answered or has stopped waiting."""
        return self._reply is None

    def resolve(self, result: bool, values: object) -> None:
        """Answer the caller, at most once."""
        reply, self._reply = self._reply, None
        settled, self.on_settled = self.on_settled, None
        if settled is not None:
            settled()
        if reply is not None:
            reply(result, values)

    def forget(self) -> None:
        """The caller stopped waiting (timeout or disconnect)."""
        self._reply = None
        if self.cancel_job is not None:
            self.cancel_job()


@dataclass(eq=False)
class ServiceEntry:
    """One advertised service.

    Attributes:
        name: resolved name; ``spelling``: as its provider wrote it (D26).
        srvtype: the service type.
        owner: the providing participant.
        provider: the session to forward requests to, for client-advertised services.
        handler: the callable, for in-process services.
        caller_handler: the callable, for in-process services told who calls.
        amend: applied to each checked response of an in-process service (used
            to add fields a client expects beyond the type, see rosapi get_time).
        pending: request id -> call, for client-advertised services.
        running: the calls an in-process async handler is answering.
    """

    name: str
    spelling: str
    srvtype: ServiceType
    owner: ClientId
    provider: ServiceProvider | None = None
    handler: LocalServiceHandler | None = None
    caller_handler: CallerServiceHandler | None = None
    amend: Amend | None = None
    pending: dict[str, PendingCall] = field(default_factory=dict)
    running: dict[PendingCall, None] = field(default_factory=dict)
    counter: itertools.count[int] = field(default_factory=lambda: itertools.count(1))

    @property
    def type_name(self) -> str:
        """The canonical service type (``std_srvs/srv/SetBool``)."""
        return self.srvtype.name

    def end_all(self, reason: str) -> None:
        """Answer every pending call with ``result: false`` (D4, D15).

        An in-process handler's jobs are cancelled: their answers have nowhere to go.
        One failing reply does not keep the others from theirs.
        """
        calls, self.pending = list(self.pending.values()), {}
        running, self.running = list(self.running), {}
        for call in calls + running:
            guarded(f"failing a call to {self.spelling}", partial(call.resolve, False, reason))
        for call in running:
            if call.cancel_job is not None:
                call.cancel_job()

    def tell_lost(self, reason: str) -> None:
        """Warn a client provider that its service was replaced (D15)."""
        if self.provider is not None:
            self.provider.on_service_lost(self.spelling, reason)


class Services(ProviderTable[ServiceEntry]):
    """The service table of a graph (see ``ProviderTable`` for the arguments)."""

    def __init__(
        self, registry: TypeRegistry, clock: Clock, spawner: Callable[[], Spawner | None]
    ) -> None:
        super().__init__("service", registry, clock, spawner)
        # caller -> its calls waiting on client providers, so that a caller's
        # release costs its own calls, not every pending call of the graph
        self._calls_of: dict[ClientId, set[tuple[ServiceEntry, str]]] = {}
        #: links that may still discover a service nobody offers (``DiscoveryWait``)
        self.discoveries: list[DiscoveryWait] = []
        self._parked: dict[str, list[_Parked]] = {}  # resolved name -> calls waiting for it

    def call(
        self,
        client: ClientId,
        service: str,
        args: object,
        reply: ServiceReply,
        *,
        type_name: str | None = None,
        timeout_s: float | None = None,
        path: str = "$",
    ) -> PendingCall:
        """Start a call to ``service`` with ``args``, of ``type_name`` when given (spec 3.3.8).

        A client provider gets the request as a ``CallService`` op of its own:
        the service as it spelled it, the request in the internal form, and the
        id ``service_request:<name>:<n>``.

        A service nobody offers while a link may still discover it
        (``discoveries``) is waited for: up to ``timeout_s`` when the caller gave
        one (its timeout then ends the call, ``Pending.forget``), else as long as
        the link says; the call starts if the service comes, else fails as unknown
        (``result: false``).

        Raises:
            UnknownNameError: the service does not exist (and no link waits for it).
            GraphError: the service has another type, or its
                client provider is busy (docs/limits.md).
            FieldError: ``args`` does not fit the request type.
        """
        entry = self.entries.get(resolve_name(service))
        if entry is None:
            call = PendingCall(client, reply)
            if not self._park(_Parked(call, service, args, type_name, path, []), timeout_s):
                raise UnknownNameError("service", service)
            return call
        return self._start(entry, PendingCall(client, reply), service, args, type_name, path)

    def _start(
        self,
        entry: ServiceEntry,
        call: PendingCall,
        service: str,
        args: object,
        type_name: str | None,
        path: str,
    ) -> PendingCall:
        client = call.caller
        if type_name is not None and self.registry.service(type_name).name != entry.srvtype.name:
            raise GraphError(f"service {service} has type {entry.srvtype.name}, not {type_name}")
        request = convert_args(entry.srvtype.request, args, path=path, now=self.clock.wall())
        if entry.caller_handler is not None:
            self._run_local(entry, _with_caller(entry.caller_handler, client), request.msg, call)
        elif entry.handler is not None:
            self._run_local(entry, entry.handler, request.msg, call)
        else:
            assert entry.provider is not None
            request_id = f"service_request:{entry.spelling}:{next(entry.counter)}"
            entry.pending[request_id] = call
            self._track(call, entry, request_id)
            try:
                entry.provider.on_service_request(
                    CallService(service=entry.spelling, args=request.msg, id=request_id)
                )
            except RwtError as exc:  # refused (provider busy): the caller fails, nothing waits
                del entry.pending[request_id]
                self._untrack(call.caller, (entry, request_id))
                self.log_refusal(entry.spelling, client, exc.message)
                raise
        return call

    def _park(self, parked: _Parked, timeout_s: float | None) -> bool:
        """Hold a call to a service a link may still discover; False if no link waits."""
        if not self.discoveries:
            return False
        name = resolve_name(parked.service)
        # a caller that said how long it waits is held that long: a node starting
        # on a loaded machine may take longer to discover than a link's own wait
        expire = _kept if timeout_s is not None else partial(self._expire, name, parked)
        for wait in self.discoveries:
            cancel = wait(expire)
            if cancel is not None:
                parked.cancels.append(cancel)
        if not parked.cancels:
            return False
        parked.waits = len(parked.cancels)
        self._parked.setdefault(name, []).append(parked)

        def forget() -> None:  # the caller stopped waiting (its timeout, its disconnect)
            self._unpark(name, parked)

        parked.call.cancel_job = forget
        return True

    def _unpark(self, name: str, parked: _Parked) -> bool:
        """Stop holding ``parked`` (started, expired or forgotten); False if it was not held."""
        waiting = self._parked.get(name, [])
        if parked not in waiting:
            return False
        waiting.remove(parked)
        if not waiting:
            del self._parked[name]
        for cancel in parked.cancels:
            cancel()
        parked.call.cancel_job = None
        return True

    def _expire(self, name: str, parked: _Parked) -> None:
        """A link's wait is over: the call fails as unknown unless another link still waits."""
        parked.waits -= 1
        if parked.waits > 0:
            return  # another link's wait is still on: its expiry decides
        if self._unpark(name, parked):
            parked.call.resolve(False, UnknownNameError("service", parked.service).message)

    def advertise(self, entry: ServiceEntry) -> None:
        """Add ``entry`` (``ProviderTable.advertise``), then start the calls that waited for it."""
        super().advertise(entry)
        for parked in list(self._parked.get(entry.name, ())):
            self._unpark(entry.name, parked)
            call = parked.call
            try:
                self._start(entry, call, parked.service, parked.args, parked.type_name, parked.path)
            except RwtError as exc:  # another type, arguments that do not fit, a busy provider
                call.resolve(False, exc.message)

    def respond(
        self,
        client: ClientId,
        service: str,
        request_id: str | int | None,
        result: bool,
        values: object,
        *,
        path: str = "$",
    ) -> None:
        """Route a provider's ``service_response`` to its caller (spec 3.3.9, D15, D28).

        ``request_id`` names the request (the id of the ``CallService`` the
        provider got); ``values`` is the response when ``result`` is true, else
        the reason its caller gets when it is a text.

        Raises:
            GraphError: ``client`` does not provide ``service``; no or an
                unknown request id (warning: it may have timed out).
            FieldError: ``values`` does not fit the response type (the caller gets
                ``result: false`` too).
        """
        entry = self.owned(client, service)
        if request_id is None:
            raise GraphError(f"service_response for {service} names no request id")
        key = str(request_id)
        call = entry.pending.pop(key, None)
        if call is None:
            raise GraphError(f"no pending request {key!r} for {service}", level=StatusLevel.WARNING)
        if not result:
            call.resolve(False, values if isinstance(values, str) else "service call failed")
            return
        try:
            response = entry.srvtype.response.from_json(
                {} if values is None else values, path=path, now=self.clock.wall()
            )
        except FieldError as exc:
            call.resolve(False, f"invalid response from the provider: {exc.message}")
            raise
        call.resolve(True, response.msg)

    def release(self, client: ClientId) -> None:
        """Drop the services ``client`` provides; forget its own pending calls.

        Costs what ``client`` provides and calls, not the size of the table.
        """
        for entry in self.take_owned(client):
            entry.end_all(f"service {entry.spelling} is gone: its provider disconnected")
        for name, waiting in list(self._parked.items()):
            for parked in [p for p in waiting if p.call.caller == client]:
                self._unpark(name, parked)
        for entry, request_id in list(self._calls_of.pop(client, ())):
            call = entry.pending.get(request_id)
            if call is not None and call.caller == client:
                del entry.pending[request_id]
                call.on_settled = None

    def _track(self, call: PendingCall, entry: ServiceEntry, request_id: str) -> None:
        key = (entry, request_id)
        self._calls_of.setdefault(call.caller, set()).add(key)
        call.on_settled = partial(self._untrack, call.caller, key)

    def _untrack(self, caller: ClientId, key: tuple[ServiceEntry, str]) -> None:
        calls = self._calls_of.get(caller)
        if calls is not None:
            calls.discard(key)
            if not calls:
                del self._calls_of[caller]

    def _run_local(
        self, entry: ServiceEntry, handler: LocalServiceHandler, request: Message, call: PendingCall
    ) -> None:
        try:
            outcome = handler(request)
        except RwtError as exc:  # a refusal with a reason (rosapi: unknown type...), not a bug
            logger.debug("service %s refused a call: %s", entry.spelling, exc.message)
            call.resolve(False, f"service {entry.spelling} failed: {exc.message}")
            return
        except Exception as exc:
            _failed(entry, call, exc)
            return
        if not inspect.isawaitable(outcome):
            self._finish(entry, outcome, call)
            return
        spawner = self._spawner()
        if spawner is None:
            _discard(outcome)
            call.resolve(False, f"service {entry.spelling} is async but no event loop runs it")
            return

        async def wait() -> None:
            try:
                response = await outcome
            except Exception as exc:
                _failed(entry, call, exc)
            else:
                self._finish(entry, response, call)
            finally:
                entry.running.pop(call, None)

        cancel = spawner(wait)

        def cancel_job() -> None:  # also before the job ran: it may never run
            entry.running.pop(call, None)
            cancel()

        entry.running[call] = None
        call.cancel_job = cancel_job

    def _finish(self, entry: ServiceEntry, response: object, call: PendingCall) -> None:
        try:
            msg = entry.srvtype.response.from_python(response, now=self.clock.wall())
        except (FieldError, GraphError) as exc:
            call.resolve(False, f"service {entry.spelling} returned an invalid response: {exc}")
            return
        call.resolve(True, msg if entry.amend is None else entry.amend(msg))


def _failed(entry: ServiceEntry, call: PendingCall, exc: Exception) -> None:
    """Tell the caller that an in-process handler raised, and log it once per episode.

    A bug of the embedding program; its callers decide how often it happens.
    """
    _episodes.log(
        logging.ERROR,
        f"service_failed {entry.name}",
        "service %s failed",
        entry.spelling,
        exc_info=True,
    )
    call.resolve(False, f"service {entry.spelling} failed: {exc}")


def _with_caller(handler: CallerServiceHandler, caller: ClientId) -> LocalServiceHandler:
    return lambda request: handler(caller, request)


def _discard(awaitable: Awaitable[object]) -> None:
    close = getattr(awaitable, "close", None)
    if close is not None:
        close()  # a coroutine that will never run: close it to avoid a warning
