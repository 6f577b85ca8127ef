"""The in-memory robot graph: topics, services, actions, parameters and types.

Sessions (``rwt_protocol``), links to other middleware (``rwt_zenoh``,
``rwt_ros2``) and Python code in the same process all attach to one graph.
The graph does no network I/O; its two waits (``async_calls``, the TF
republisher's ticks) use anyio's events and sleep in the caller's loop, and
``tasks`` starts a task from a plain loop callback.
docs/architecture.md shows where it sits.

Modules:

- ``graph``: ``Graph``, the graph as Python code in the same process sees it
  (the embedding API).
- ``core``: the graph's state and the port (``rwt_protocol.ports``) that
  sessions and links drive, in the graph's terms.
- ``port``: ``GraphFront``, the graph as a protocol front end sees it (the
  port's calls, the feed, types, nodes, timeline); what other packages type against.
- ``feed``: the change feed: every entity a participant gains or loses, announced
  once, with versions (instead of rescanning the graph).
- ``visibility``: which names a client may see, one rule for rosapi's and
  Foxglove's listings, built from the access rules.
- ``topics``: topics: advertisers, subscribers, latching, delivery (spec 3.3.1-3.3.5).
- ``topic_qos``: a topic's QoS (protocol 2.1.0's ``qos``): its offer, the
  transient-local store, lifespan, subscribers a request cannot match (D62-D64).
- ``services``: services: providers, calls and their replies (spec 3.3.6-3.3.9).
- ``actions``: actions: goals, feedback, results, cancels (spec 3.3.10-3.3.15).
- ``action_status``: each served action's ``_action/status`` topic (ROS 2), as
  ROS 2 action servers publish it.
- ``calls``: what service calls and action goals share: arguments, pending records.
- ``async_calls``: ``call_service`` and ``send_action_goal`` for Python callers.
- ``local``: handles of in-process publishers, subscribers and providers.
- ``nodes``: node names of the graph's participants, for rosapi.
- ``clock``: the clocks the graph reads (monotonic for order, wall for stamps).
- ``simtime``: the latest ``/clock`` as the graph's timeline (``use_sim_time``).
- ``playback``: what a running player offers (status, rate, seek) beside the timeline.
- ``ratelog``: peer-triggered log lines once per episode, on the process's clock.
- ``tasks``: a task group's task started from any code on the loop, a plain
  callback that another thread scheduled included (a link's hand-over).
- ``link``: the link contract: how a graph is mirrored to and from another middleware.
- ``mirror``: the other middleware's entities as participants of the graph, one
  mirror for both links (they supply discovery, transport and codecs).
- ``exports``: a link's outward side: the local entities it shares, followed
  through the change feed, with one backlog of what changed.
- ``topic_holds``: a link's topics held back while the subscribers they congested
  catch up.

Subpackages:

- ``types``: the message type registry, ``.msg``/``.srv``/``.action`` parsing, and
  conversion between JSON, messages, CDR and rosbags.
- ``parameters``: the parameter store and its bridge to ROS 2 nodes' parameter
  services (``store``, ``wire``, ``services``, ``replicas``).
- ``rosapi``: the built-in ``/rosapi/*`` services (introspection, parameters), and
  each node's own ROS 2 parameter services (``nodeparams``).
- ``tf``: a transform buffer and the built-in tf2_web_republisher.
- ``media``: images as numpy arrays and the depth-cloud codec.
- ``safety``: the safety envelope: rules, bounded fields, the check every remote
  client's publish passes, dead-man stops, the audit trail (docs/safety.md).
- ``interfaces``, ``interfaces_ros1``: the shipped message definitions (data, no code).
"""
