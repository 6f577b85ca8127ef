"""An MCP (Model Context Protocol) server: AI agents drive a robot through its tools.

The tools (docs/agents.md, docs/mcp.md) are written once, against ``robot.Robot``,
which two things implement: for ``rwt serve --mcp``, each MCP session is a session
of the server's connection runtime (``session.McpSession``, served by
``rwt_transports.http.mcp``), which calls the graph directly under every per-client
rule; for ``rwt mcp URL``, in front of any rosbridge server, ``robot.ClientRobot``
over one persistent rosbridge connection made with rwt's client (``rwt_client``).
Modules:

- ``cli``: the ``rwt mcp`` command, MCP over stdio;
- ``tools``: the tools (graph, topics, services, actions, parameters, TF) and
  the MCPServer that offers them (the official SDK's, D52);
- ``catalog``: the tools declared once: each one's safety class and access rule;
- ``guard``: what a session may do (access rules, read-only mode, rate and
  size caps) and the log of its writes;
- ``approval``: a person's approval before a tool acts where the safety rules ask;
- ``resources``: topics as resources, read and subscribed to;
- ``link``: the session's connection to its robot, its publishers and the goals it sent;
- ``robot``: ``Robot``, the robot as the tools see it, and ``ClientRobot``;
- ``session``: ``McpSession``, an MCP session of the connection runtime (``rwt serve
  --mcp``): the robot's graph, called directly;
- ``tasks``: goals as MCP tasks (the Tasks extension), shared by a front end's sessions;
- ``app``: the robot's MCP App (a camera and a drive pad, served from ``static``);
- ``render``: bounded message text, JSON schemas of message types, images.

Needs the ``mcp`` extra (the official MCP Python SDK).
"""
