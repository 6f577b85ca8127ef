"""rwt on Zenoh: the rmw_zenoh wire, so rwt processes and ROS 2 nodes share one graph.

``rwt_zenoh.wire`` is the mapping itself, sans-IO: key expressions, liveliness
tokens, QoS strings, type names and hashes, and the sample attachment, as
rmw_zenoh writes them (docs/zenoh.md names the rmw_zenoh version followed).
"""
