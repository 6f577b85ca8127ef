"""The server runtime: the server, its front ends, the transports, the connection pump.

The ``rwt`` command line that starts it lives in ``rwt_cli``, above this package;
the connection runtime every session shares (and flow control) is
``rwt_protocol.runtime``, below it (docs/architecture.md). Modules and rooms, each
line importing only those on its line or below it (an import contract keeps the
order):

- ``server``: ``GraphServer``: the listeners, one admission, the one entry check,
  the front ends made from the registry;
- ``frontends_registry``: the one registry of the front ends (``SOCKET_FRONTENDS``,
  ``HTTP_FRONTENDS``, rosbridge's default) and where the settings hold their options;
- ``config``: ``ServerConfig``, what ``rwt serve`` maps its options onto;
- ``websocket``, ``tcp``, ``stdio``: the stream transports' listeners and channels;
  ``udp``: the datagram transport; ``gates``: the links' gates, by which a served
  graph's links take part in flow control;
- ``rosbridge``: rosbridge, the default front end (its labels, and the hooks the
  transports ask of it); ``foxglove``: the Foxglove WebSocket protocol as a front
  end; ``http``: the HTTP front ends on the WebSocket port (the HTTP API,
  ``/version``, MCP); ``webrtc``: WebRTC: signalling, peers, their data channels and
  video tracks;
- ``memory``: the in-process transport; ``workers``: the processes of
  ``rwt serve --workers N`` and topic placement;
- ``host``: ``FrontEndHost`` and ``SessionHost``, what a front end and a listener
  know of the server (an interface, not the server);
- ``pump``: the connection pump: one session driven over one channel, any protocol;
- ``admission``: a connection's way in: its turn, its host's share, what it holds
  before it is admitted; ``holding``: holds carried out, as flow control decides;
  ``gather``: output made outside a reader's batch, gathered over loop turns;
  ``channel``: ``Channel`` and ``ChannelAbilities``, a connection's frame I/O;
- ``direct``: the asyncio transport under an anyio socket stream, used directly;
  ``sendqueue``: how much a socket's kernel still holds for its peer; ``writes``:
  outgoing frames joined into few writes; ``wsread``: whole WebSocket messages taken
  off the stream before websockets' parser; ``frontends``: ``FrontEnd`` and
  ``FrontEnds``, a protocol as the listeners choose it; ``listen``: the error of a
  listener that cannot bind its address; ``deadman``: the safety envelope's timer;
  ``rosauth``: rosauth's MAC check as the authenticator (D23, D31, D33);
  ``process``: what a server's process tunes (its heap, its collector, descriptors).
"""
