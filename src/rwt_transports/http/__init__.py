"""The HTTP front ends on the WebSocket port: the HTTP API, /version, MCP."""
