"""The server role of the protocol: one connection's session and everything it holds.

``session.Session`` is the state machine a transport drives (frames and timer
ticks in, frames and commands out): a ``connection.SessionBase``, the part every
protocol's session shares (the contract the connection runtime drives is
``contract.ServerSession``). Around it, one module a job:

- ``handlers``: one handler per op, over ``handlers.HandlerContext`` (the session
  as handlers see it);
- ``lifecycle`` (its states), ``holdings`` (what it holds in the graph),
  ``subscriptions`` (one topic's merged subscriptions);
- ``callbook`` (the calls in flight: a cap, a deadline each, answered once);
- ``gates`` (authentication, then ``access`` rules, before each handler) and
  ``replies`` (what a refused request gets besides its status);
- ``encoding`` (topic messages and replies in each subscriber's encoding),
  ``outbox`` (the bounded queue of outgoing frames), ``lossy`` (the latest
  message of each topic subscribed on a transport's lossy channel, D36),
  ``backpressure`` (slow consumers), ``inflate`` (the png inflation budget),
  ``pngout`` (png messages deflated off the event loop), ``memory`` (the
  server-wide memory budget every connection is charged to, D44);
- ``timers``, ``idle`` (closing silent connections), ``commands`` (what the
  session asks its transport to do).
"""
