"""What a server's process tunes: its heap, its collector, its descriptor budget."""
