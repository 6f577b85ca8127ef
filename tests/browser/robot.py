"""The robot the browser tests look at: roslibpy publishing, subscribing and serving.

Usage: python robot.py HOST PORT. Runs as its own process (roslibpy's reactor
runs once per process); prints ``ready`` once everything is advertised, then one
JSON line per message received on /console_test/command; stops when stdin closes.
"""

from __future__ import annotations

import base64
import json
import math
import os
import sys
import threading
import time
from typing import Any

import roslibpy

WIDTH, HEIGHT = 64, 48
RED, BLUE = (220, 30, 30), (30, 30, 220)


def image() -> dict[str, Any]:
    """rgb8, the left half red, the right half blue."""
    row = [*RED] * (WIDTH // 2) + [*BLUE] * (WIDTH // 2)
    return {
        "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "camera"},
        "height": HEIGHT,
        "width": WIDTH,
        "encoding": "rgb8",
        "is_bigendian": 0,
        "step": WIDTH * 3,
        "data": row * HEIGHT,
    }


def noise(width: int = 160, height: int = 120) -> dict[str, Any]:
    """rgb8 noise, new every call: a video encoder has something to encode each frame."""
    return {
        "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "camera"},
        "height": height,
        "width": width,
        "encoding": "rgb8",
        "is_bigendian": 0,
        "step": width * 3,
        "data": base64.b64encode(os.urandom(width * height * 3)).decode(),  # uint8[] as base64
    }


def transform(parent: str, child: str, x: float) -> dict[str, Any]:
    return {
        "header": {"stamp": {"sec": int(time.time()), "nanosec": 0}, "frame_id": parent},
        "child_frame_id": child,
        "transform": {
            "translation": {"x": x, "y": 0.0, "z": 0.0},
            "rotation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
        },
    }


def room(width: int = 80, height: int = 60) -> dict[str, Any]:
    """A nav_msgs/OccupancyGrid of a walled room at 5 cm a cell, its origin at (-1, -1.5) m."""
    data = []
    for row in range(height):
        for col in range(width):
            wall = row in (0, height - 1) or col in (0, width - 1)
            table = 50 <= col < 62 and 20 <= row < 32
            data.append(100 if wall else -1 if table else 0)
    origin = {"position": {"x": -1.0, "y": -1.5, "z": 0.0}, "orientation": {"w": 1.0}}
    info = {"resolution": 0.05, "width": width, "height": height, "origin": origin}
    return {"header": {"frame_id": "map"}, "info": info, "data": data}


class Robot:
    """A roslibpy client that publishes a chatter, images and TF, and serves /console_test/add.

    What arrives on /console_test/command (published by the page) is printed as JSON.
    """

    def __init__(self, host: str, port: int) -> None:
        self.ros = roslibpy.Ros(host, port)
        self.ros.run(timeout=10)
        self.count = 0
        self._stop = threading.Event()
        self.chatter = roslibpy.Topic(self.ros, "/console_test/chatter", "std_msgs/msg/String")
        self.point = roslibpy.Topic(self.ros, "/console_test/point", "geometry_msgs/msg/Point")
        self.camera = roslibpy.Topic(self.ros, "/camera/image", "sensor_msgs/msg/Image")
        self.noise = roslibpy.Topic(self.ros, "/camera/noise", "sensor_msgs/msg/Image")
        self.tf = roslibpy.Topic(self.ros, "/tf", "tf2_msgs/msg/TFMessage")
        self.tf_static = roslibpy.Topic(self.ros, "/tf_static", "tf2_msgs/msg/TFMessage")
        for topic in (self.chatter, self.point, self.camera, self.noise, self.tf, self.tf_static):
            topic.advertise()
        self.command = roslibpy.Topic(self.ros, "/console_test/command", "std_msgs/msg/String")
        self.command.subscribe(lambda msg: print(json.dumps(msg), flush=True))
        self.cmd_vel = roslibpy.Topic(self.ros, "/cmd_vel", "geometry_msgs/msg/Twist")
        self.cmd_vel.subscribe(lambda msg: print(json.dumps({"cmd_vel": msg}), flush=True))
        self.service = roslibpy.Service(
            self.ros, "/console_test/add", "example_interfaces/srv/AddTwoInts"
        )
        self.service.advertise(self._add)
        self.lights_on: list[bool] = []
        self.lights = roslibpy.Service(self.ros, "/console_test/lights", "std_srvs/srv/SetBool")
        self.lights.advertise(self._switch)
        # the page publishes here; an out-of-range value is refused by the server
        self.level = roslibpy.Topic(self.ros, "/console_test/level", "std_msgs/msg/Int8")
        self.level.advertise()
        # a latched 4 m x 3 m room for the Map tab (its screenshot): walls occupied,
        # a table unknown, the floor free
        self.map = roslibpy.Topic(self.ros, "/map", "nav_msgs/msg/OccupancyGrid", latch=True)
        self.map.advertise()
        self.map.publish(roslibpy.Message(room()))
        self.rosout = roslibpy.Topic(self.ros, "/rosout", "rcl_interfaces/msg/Log")
        self.rosout.advertise()
        self._thread = threading.Thread(target=self._publish, daemon=True)
        self._thread.start()

    @staticmethod
    def _add(request: dict[str, Any], response: dict[str, Any]) -> bool:
        response["sum"] = request["a"] + request["b"]
        return True

    def _switch(self, request: dict[str, Any], response: dict[str, Any]) -> bool:
        self.lights_on.append(request["data"])
        response["success"] = request["data"] is True
        response["message"] = f"lights {'on' if request['data'] else 'off'}"
        return True

    def _publish(self) -> None:
        frame = image()
        while not self._stop.wait(0.1):
            self.count += 1
            self.chatter.publish(roslibpy.Message({"data": f"hello {self.count}"}))
            wave = math.sin(self.count / 5)
            self.point.publish(roslibpy.Message({"x": wave, "y": -wave, "z": 0.5}))
            if self.count % 2 == 0:
                self.camera.publish(roslibpy.Message(frame))
            self.noise.publish(roslibpy.Message(noise()))
            self.tf.publish(roslibpy.Message({"transforms": [transform("odom", "base_link", 0.1)]}))
            if self.count % 5 == 0:
                level, text = (30, "battery low") if self.count % 10 == 0 else (20, "tick")
                stamp = {"sec": int(time.time()), "nanosec": 0}
                line = {"stamp": stamp, "level": level, "name": "robot", "msg": text}
                self.rosout.publish(roslibpy.Message(line))
            if self.count % 10 == 1:  # latched or not, the page sees it within a second
                static = [transform("map", "odom", 1.0), transform("base_link", "camera", 0.2)]
                self.tf_static.publish(roslibpy.Message({"transforms": static}))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)
        self.ros.terminate()


if __name__ == "__main__":
    robot = Robot(sys.argv[1], int(sys.argv[2]))
    time.sleep(0.5)  # the advertisements reach the server before the test looks
    print("ready", flush=True)
    sys.stdin.read()  # until the test closes it
    robot.close()
