"""What the detector saw, drawn on the frame: for `skyring detect --preview` and the operator's thumbnail."""

from __future__ import annotations

import numpy as np

from vehicles.detect.camera_source import CameraStatus
from vehicles.detect.pixels import PersonPixels

GREEN, AMBER, RED, WHITE, GREY = (60, 200, 60), (0, 180, 255), (40, 40, 230), (255, 255, 255), (160, 160, 160)


def draw_overlay(
    image_bgr: np.ndarray,
    *,
    person: PersonPixels | None,
    others: tuple[PersonPixels, ...] = (),
    status: CameraStatus | None = None,
    fps: float = float("nan"),
    label: str = "",
) -> np.ndarray:
    """A copy of image_bgr with the followed person (box, head and feet points with their confidences), the
    other people found (grey), and a status line (camera state, frames per second)."""
    import cv2

    out = image_bgr.copy()
    scale = max(out.shape[1] / 1000.0, 0.5)
    thick = max(int(round(2 * scale)), 1)
    for p in others:
        x0, y0, x1, y1 = (int(round(v)) for v in p.box_px)
        cv2.rectangle(out, (x0, y0), (x1, y1), GREY, max(thick // 2, 1))
    if person is not None:
        colour = GREEN if person.confidence >= 0.6 else AMBER
        x0, y0, x1, y1 = (int(round(v)) for v in person.box_px)
        cv2.rectangle(out, (x0, y0), (x1, y1), colour, thick)
        for (u, v), conf in ((person.head_px, person.head_conf), (person.feet_px, person.feet_conf)):
            c = (int(round(u)), int(round(v)))
            cv2.drawMarker(out, c, RED, cv2.MARKER_CROSS, int(16 * scale), thick)
            cv2.putText(
                out, f"{conf:.2f}", (c[0] + 8, c[1]), cv2.FONT_HERSHEY_SIMPLEX, 0.5 * scale, colour, thick
            )
    parts = [label] if label else []
    if status is not None:
        parts.append(f"camera {status.state}")
        if status.corrupt:
            parts.append(f"{status.corrupt} corrupt")
        if status.reconnects:
            parts.append(f"{status.reconnects} reconnects")
    if fps == fps:
        parts.append(f"{fps:.1f} fps")
    parts.append("person" if person is not None else "no person")
    text = " | ".join(parts)
    cv2.putText(out, text, (10, int(30 * scale)), cv2.FONT_HERSHEY_SIMPLEX, 0.7 * scale, (0, 0, 0), thick + 2)
    cv2.putText(out, text, (10, int(30 * scale)), cv2.FONT_HERSHEY_SIMPLEX, 0.7 * scale, WHITE, thick)
    return out


def thumbnail_jpeg(
    image_bgr: np.ndarray, *, width_px: int = 320, quality: int = 70, max_bytes: int = 12_000
) -> bytes:
    """A small JPEG of image_bgr, width_px wide, for the operator page: at `quality`, lowered in steps of 10
    (to 20 at least) until it fits max_bytes (it travels in one network message)."""
    import cv2

    h, w = image_bgr.shape[:2]
    k = width_px / float(w)
    small = cv2.resize(image_bgr, (width_px, max(int(round(h * k)), 1)), interpolation=cv2.INTER_AREA)
    q = int(quality)
    while True:
        ok, buf = cv2.imencode(".jpg", small, [cv2.IMWRITE_JPEG_QUALITY, q])
        if not ok:
            raise ValueError("JPEG encoding failed")
        if buf.size <= max_bytes or q <= 20:
            return buf.tobytes()
        q -= 10
