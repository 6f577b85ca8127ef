"""The variants of B1, B2 and B4: one publisher, window-limited, byte-exact checks."""

from __future__ import annotations

import math
from functools import partial

from .. import msgs
from .checks import med, ratio_at_least, ratio_of
from .common import Context, Medians, Metrics, Run, Variant
from .throughput import Stream, stream_run

__all__ = ["STRING", "TWIST", "image_stream", "throughput_variants"]

STRING = Stream("/b1", "std_msgs/msg/String", partial(msgs.string_publish, "/b1"))
TWIST = Stream("/b1t", "geometry_msgs/msg/Twist", partial(msgs.twist_publish, "/b1t"))
B1_STRING_KEY = "B1 String 100 B, 1 -> 1"


def image_stream(size_mb: int, compression: str) -> Stream:
    """``sensor_msgs/Image`` mono8 of ``size_mb`` MiB, published as CBOR."""
    side = 1024 * int(math.sqrt(size_mb))
    width, height = (side, side) if size_mb != 2 else (2048, 1024)
    topic = f"/b4_{size_mb}mb"
    return Stream(
        topic,
        "sensor_msgs/msg/Image",
        lambda i: msgs.image_cbor(topic, i, width, height),
        binary=True,
        compression=compression,
        period=4,
        payload_bytes=width * height,
    )


def _stream(stream: Stream, subscribers: int, duration_s: float) -> callable:  # type: ignore[valid-type]
    def run(run: Run) -> Metrics:
        return stream_run(run, stream, subscribers=subscribers, duration_s=duration_s)

    return run


def _fanout_check(subscribers: int) -> callable:  # type: ignore[valid-type]
    """B2: deliveries/s >= 1.0x bare; <= 4 us server CPU per extra subscriber."""

    def check(medians: Medians, context: Context) -> tuple[str, str, bool | None]:
        ratio = ratio_of(medians, "deliveries_per_s")
        one = med(context.get(B1_STRING_KEY, {}), "rwt", "server_cpu_us_per_msg")
        many = med(medians, "rwt", "server_cpu_us_per_msg")
        extra = (many - one) / (subscribers - 1)
        shown = f"{ratio:.2f}x; {extra:.1f} us/extra sub"
        target = ">= 1.0x bare; <= 4 us/extra sub"
        if math.isnan(ratio):
            return shown, target, None
        return shown, target, ratio >= 1.0 and (math.isnan(extra) or extra <= 4.0)

    return check


def throughput_variants() -> list[Variant]:
    """B1, B2 and B4 (docs/benchmarks.md)."""
    variants = [
        Variant(
            "B1",
            "String 100 B, 1 -> 1",
            _stream(STRING, 1, 1.5),
            "msg_per_s",
            "msg/s",
            ratio_at_least("msg_per_s", 0.7, cpu_bound=2.0),
        ),
        Variant(
            "B1",
            "Twist 124 B, 1 -> 1",
            _stream(TWIST, 1, 1.5),
            "msg_per_s",
            "msg/s",
            ratio_at_least("msg_per_s", 0.7, cpu_bound=2.0),
        ),
    ]
    for count in (10, 100):
        variants.append(
            Variant(
                "B2",
                f"String 100 B, 1 -> {count}",
                _stream(STRING, count, 1.5),
                "deliveries_per_s",
                "deliveries/s",
                _fanout_check(count),
            )
        )
    for size in (1, 4):
        for compression in ("cbor", "cbor-raw"):
            for count in (1, 10):
                variants.append(
                    Variant(
                        "B4",
                        f"Image {size} MiB {compression}, 1 -> {count}",
                        _stream(image_stream(size, compression), count, 1.5),
                        "mb_per_s",
                        "MB/s",
                        ratio_at_least("mb_per_s", 0.7),
                    )
                )
    return variants
