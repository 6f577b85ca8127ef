"""Parameters: the graph's store and its bridge to ROS 2 nodes' parameter services.

- ``store``: the in-memory parameter store (rosapi's get/set/has/delete_param),
  its limits and each node's share of it.
- ``wire``: values as ``rcl_interfaces/msg/ParameterValue``, both ways.
- ``services``: answers of a node's ROS 2 parameter services, from the store.
- ``replicas``: copies of other nodes' parameters, refreshed through their services.
"""
