"""How a connection gets in: its turn, its host's share, what it holds before admission."""
