"""The HTTP front ends on the WebSocket port: the HTTP API, ``GET /version``, MCP.

Each is an ``endpoint.HttpEndpoint`` the server makes from its entry in the
registry (``rwt_transports.frontends_registry.HTTP_FRONTENDS``) and offers the
requests whose first bytes it claims, before the WebSocket handshake takes them
(docs/architecture.md, "How to add"). Each knows the server as a
``rwt_transports.host.FrontEndHost``. Modules, each importing only those after it:

- ``api``: the HTTP API's transport (docs/http.md): its paths, one pump per request
  over ``HttpChannel``; the front end itself is ``rwt_http``;
- ``documents``: the OpenAPI documents' builds, a slice a turn of the loop (D59);
- ``mcp``: MCP over Streamable HTTP (``rwt serve --mcp``, docs/mcp.md): each MCP
  session, and each 2026-07-28 request, a session of the connection runtime;
- ``version``: ``GET /version``: the protocol and server versions, and what the
  server offers (D49);
- ``mcp_options``: ``McpOptions`` and MCP's paths, apart so the configuration names
  them without loading the MCP SDK;
- ``endpoint``: what every endpoint shares: ``HttpEndpoint``, claiming a request by
  its first bytes, ``open_request`` (the one reader, bounded before admission, D58),
  ``reply``;
- ``host_rates``: a paced rate per host (MCP's sessions a second from one host);
- ``mcp_siblings``: MCP under ``--workers N``: a request goes to the worker holding
  its session or task.
"""
