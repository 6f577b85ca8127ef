"""Table III (paper IV.D): PNG compression of large messages, from ``png_compression.py``."""

from __future__ import annotations

from benchmarks.png_compression import measure_all

__all__ = ["run"]

FIGURE = "Table III"


def run(quick: bool) -> list[dict[str, object]]:
    """Size after compression and time per message, next to the paper's (medians).

    ``quick`` measures once instead of the median of 9.
    """
    rows: list[dict[str, object]] = []
    for r in measure_all(1 if quick else 9):
        paper = r["paper"]
        assert isinstance(paper, dict)
        name = r["name"]
        rows += [
            {
                "figure": FIGURE,
                "metric": f"{name}: original",
                "paper": paper["original_kb"],
                "ours": r["json_kb"],
                "unit": "KB",
                "note": "JSON of the publish op",
            },
            {
                "figure": FIGURE,
                "metric": f"{name}: compressed",
                "paper": paper["compressed_kb"],
                "ours": r["png_op_kb"],
                "unit": "KB",
                "note": "png op, base64 included",
            },
            {
                "figure": FIGURE,
                "metric": f"{name}: time",
                "paper": paper["ms"],
                "ours": r["publish_to_frame_ms"],
                "unit": "ms",
                "note": "publish -> png frame queued",
            },
        ]
    return rows
