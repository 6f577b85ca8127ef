"""The server role of rosbridge: one connection's session and everything it holds.

``session.Session`` is the state machine a transport drives (frames and timer
ticks in, frames and commands out): a ``rwt_protocol.runtime.connection.SessionBase``,
the part every protocol's session shares (the outbox, the slow-consumer watch,
timers, the idle timeout, the call book, the access rules and the rest of the
connection runtime live in ``rwt_protocol.runtime``). Its settings,
``session.SessionConfig``, are the shared ``runtime.rules.ClientRules`` and
rosbridge's own. Around it, one module a job:

- ``handlers``: one handler per op, over ``handlers.HandlerContext`` (the session
  as handlers see it);
- ``holdings`` (what it holds in the graph), ``subscriptions`` (one topic's
  merged subscriptions), ``subscription_qos`` (their QoS: what it asks, what the
  topic offers, the rules that follow, D63-D65);
- ``gates`` (authentication, then the access rules, before each handler;
  ``op_access`` says which name of which op each glob checks) and ``replies``
  (what a refused request gets besides its status);
- ``encoding`` (topic messages and replies in each subscriber's encoding),
  ``inflate`` (the png inflation budget), ``pngout`` (png messages deflated off
  the event loop), ``compat`` (rosbridge_suite's texts and statuses).
"""
