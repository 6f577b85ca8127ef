"""The connection runtime every protocol's server session shares, defined once.

No protocol lives here: rosbridge's session (``rwt_protocol.server``) and the
Foxglove protocol's (``rwt_foxglove``) are built on it, and so is a third
(docs/architecture.md, "How to add a protocol"). One module a job, each importing
only those listed after it (an import-linter contract keeps it so):

- ``connection``: ``SessionBase``, the per-client rules every protocol's session
  shares (timers, the idle timeout, the call book, the access gate, containment of
  a bug), made of its sender, its jobs and its lifecycle, over
- ``sender`` (``Sender``: the bounded outbox under the slow-consumer rule and the
  memory budget, ``send_frames``, the hot path ``queue_run``, the lossy lane), over
- ``backpressure`` (the slow-consumer watch), ``idle`` (closing silent
  connections), ``callbook`` (the calls in flight: a cap, a deadline each,
  answered once);
- ``contract``: ``ServerSession``, what the connection runtime
  (``rwt_transports.pump``) sees of a session, and ``LossySession``, what a
  transport with a lossy channel asks for; ``request``: ``SessionRequest``, what a
  front end makes a session from (the shared rules);
- ``lossy`` (the lane of a transport's lossy channel, D36);
- ``outbox`` (the bounded queue of outgoing frames, and ``SessionStats``, its counts
  and gauges), ``timers``, ``lifecycle`` (a connection's states and their moves, and
  ``Lifecycle``, the session's part that moves through them), ``rules``
  (``ClientRules``, the per-client rules every protocol's session is bound by),
  ``jobs`` (``Job`` and ``Jobs``, the work a session leaves to its transport);
- ``access`` (the access rules), ``memory`` (the server-wide memory budget
  every connection is charged to, D44), ``commands`` (what a session asks its
  transport to do), ``inframes`` (what a transport hands a session), ``flow``
  (flow control: who waits for whom, and for how long; sans-IO, one per event
  loop, which the pump and the links' gates carry out).
"""
