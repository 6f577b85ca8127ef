"""An MCP (Model Context Protocol) server in front of any rosbridge server: ``rwt mcp URL``.

AI agents drive a robot through its tools (docs/agents.md), over one
persistent rosbridge connection made with rwt's client (``rwt_client``):

- ``cli``: the ``rwt mcp`` command, MCP over stdio;
- ``tools``: the tools (graph, topics, services, actions, parameters, TF) and
  the FastMCP server that offers them;
- ``link``: the session's connection, its publishers and the goals it sent;
- ``render``: bounded message text, JSON schemas of message types, images.

Needs the ``mcp`` extra (the official MCP Python SDK).
"""
