"""WebRTC: sessions over a peer's data channels, video tracks to any WHEP player.

A front end of the registry (``rwt_transports.frontends_registry.WEBRTC``,
``rwt serve --webrtc``; docs/webrtc.md): an offer posted to ``/webrtc`` is admitted
on a ticket, answered by one of three stacks, and each data channel's label picks
its front end's session, which runs on the connection pump. It knows the server
as a ``rwt_transports.host.FrontEndHost``. Modules, each importing only those
after it:

- ``peers``: ``WebRtcPeers``, the peer connections (admission, the stacks, the
  sessions on the pump) and ``webrtc_endpoint``, the front end's endpoint;
- ``native_video``: video tracks sent by libdatachannel (D51);
- ``video``: video tracks on aiortc, and the shared streams both stacks send;
- ``signalling``: ``POST /webrtc`` and ``DELETE /webrtc/<id>``, WHEP style, and
  ``WebRtcOptions``;
- ``stacks``: which stack answers an offer (``--webrtc-stack``, D72);
- ``channel``: ``DataChannelChannel``, a peer's data channels as a pump channel
  (its lossy one too, D36);
- ``reactor``: the reactor stack, libwebrtc's dcsctp (D70);
- ``native``: the native stack, libdatachannel (D51);
- ``offer``: what an offer must be before anything is built for it (D38);
- ``sctp``: aiortc's SCTP receive path, bounded below aiortc (D39);
- ``ice``: the STUN and TURN servers (``--ice-server``).

``static`` holds ``roslib-transport.js``, served at ``/webrtc/roslib-transport.js``.
"""
