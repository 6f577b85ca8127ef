"""UDP: one datagram per message, one session per peer address that proved it receives."""
