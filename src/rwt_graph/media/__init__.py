"""Images as numpy arrays: ``sensor_msgs/Image`` conversion and the depth-cloud codec.

Pure numpy, no I/O: the video server (``rwt_video``) and the
depth-cloud encoder node build on these. Two modules, not loaded with this
package, hold the rule every front end's image work follows (D42):
``compressed`` (a JPEG or PNG bounded from its header before decoding, with
Pillow) and ``threads`` (the image threads of the event loop, off which the
work never runs).
"""

from __future__ import annotations

from .depthcloud import (
    CameraIntrinsics,
    DecodedDepthCloud,
    decode_depthcloud,
    encode_depthcloud,
    fill_depth_holes,
    points_from_depth,
)
from .images import (
    ImageError,
    array_to_image,
    compressed_content_type,
    depth_to_metres,
    image_to_array,
    image_to_display,
)

__all__ = [
    "CameraIntrinsics",
    "DecodedDepthCloud",
    "ImageError",
    "array_to_image",
    "compressed_content_type",
    "decode_depthcloud",
    "depth_to_metres",
    "encode_depthcloud",
    "fill_depth_holes",
    "image_to_array",
    "image_to_display",
    "points_from_depth",
]
