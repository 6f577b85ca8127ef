"""Parameters: the graph's store and its bridge to ROS 2 nodes' parameter services.

- ``store``: the in-memory parameter store (rosapi's get/set/has/delete_param),
  its limits, each node's share of it and each client's (D34).
- ``values``: values checked once and held frozen (lists as tuples, ROS 1
  namespaces as ``FrozenNamespace``), shared by every reader; their sizes.
- ``tree``: the ROS 1 tree of global names and its index of parameters.
- ``shares``: which client each parameter is charged to, and what clients left.
- ``wire``: values as ``rcl_interfaces/msg/ParameterValue``, both ways.
- ``services``: answers of a node's ROS 2 parameter services, from the store.
- ``replicas``: copies of other nodes' parameters, refreshed through their services.
"""
