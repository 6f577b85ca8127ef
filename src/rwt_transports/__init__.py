"""Transports (WebSocket, TCP, UDP, stdio), the server entry point and the CLI."""
