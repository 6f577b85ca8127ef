"""A robot for roslibjs/roslibpy users: topics, a service, an action, parameters, rosapi."""

import asyncio
import sys

from rwt import Graph, ListenError, RosbridgeServer, ServerConfig


async def fibonacci(goal: dict, context) -> dict:
    sequence = [0, 1]
    for _ in range(1, goal["order"]):
        sequence.append(sequence[-1] + sequence[-2])
        context.publish_feedback({"sequence": sequence})
        await asyncio.sleep(0.01)
    return {"sequence": sequence}


graph = Graph()
graph.params.declare("/rwt", {"max_speed": 1.0, "name": "rwt-bot"})
velocity = graph.create_publisher("/velocity", "geometry_msgs/msg/Twist", latch=True)
graph.create_subscription("/cmd_vel", velocity.publish, "geometry_msgs/msg/Twist")  # obeys at once
graph.create_service("/lights", "std_srvs/srv/SetBool", lambda req: {"success": req["data"]})
graph.create_action_server("/fibonacci", "example_interfaces/action/Fibonacci", fibonacci)
# http://127.0.0.1:9090/ shows the web console, as with rwt serve (console=False: none)
config = ServerConfig(port=int(sys.argv[1]) if sys.argv[1:] else 9090)
server = RosbridgeServer(graph, config)
try:  # Ctrl-C stops quietly; a port in use is one line on stderr and exit code 1
    asyncio.run(server.serve(on_listening=lambda url: print("listening on", url, flush=True)))
except (KeyboardInterrupt, ListenError) as exc:
    sys.exit(str(exc) or None)
