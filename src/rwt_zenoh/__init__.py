"""rwt on Zenoh: one graph shared by several processes, and by ROS 2 nodes on rmw_zenoh.

- ``wire`` and ``payload``: the rmw_zenoh mapping, sans-IO (key expressions,
  liveliness tokens, QoS strings, type names and hashes, attachments, CDR).
- ``token_qos``: the QoS the link's own tokens carry: what it delivers (D62).
- ``config``: the Zenoh session of ``rwt serve --zenoh`` (loopback and no
  multicast unless told otherwise).
- ``link``: ``ZenohLink``/``open_zenoh_link``, a graph's topics and services mirrored
  both ways; ``link_actions`` and ``link_params`` add actions and parameters.

docs/scaling.md is the user's page; docs/zenoh.md names the rmw_zenoh version followed.
"""
