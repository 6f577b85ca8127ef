"""WebRTC: sessions over a peer's data channels, video tracks to any WHEP player."""
