"""An MCP (Model Context Protocol) server in front of any rosbridge server: ``rwt mcp URL``.

AI agents drive a robot through its tools (docs/agents.md, docs/mcp.md), over
one persistent rosbridge connection made with rwt's client (``rwt_client``):
a WebSocket or TCP one for ``rwt mcp URL``, an in-process one for each
session of ``rwt serve --mcp`` (``rwt_transports.http.mcp``, which reuses
everything here):

- ``cli``: the ``rwt mcp`` command, MCP over stdio;
- ``tools``: the tools (graph, topics, services, actions, parameters, TF) and
  the MCPServer that offers them (the official SDK's, D52);
- ``guard``: what a session may do (access rules, read-only mode, rate and
  size caps) and the log of its writes;
- ``resources``: topics as resources, read and subscribed to;
- ``link``: the session's connection, its publishers and the goals it sent;
- ``tasks``: goals as MCP tasks (the Tasks extension), shared by a front end's sessions;
- ``render``: bounded message text, JSON schemas of message types, images.

Needs the ``mcp`` extra (the official MCP Python SDK).
"""
