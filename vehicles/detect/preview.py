"""`skyring detect --preview`: the overlaid frames written to a video file or a folder of JPEGs, and/or
streamed as MJPEG over HTTP (open http://HOST:PORT/ in a browser) for setting the camera up in the field."""

from __future__ import annotations

import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np

BOUNDARY = b"skyringframe"


class PreviewWriter:
    """Writes overlaid frames to PATH: a folder (one JPEG per frame) or a video file (.avi, MJPG)."""

    def __init__(self, path: str | Path, *, fps: float = 10.0) -> None:
        self._path = Path(path)
        self._fps = fps
        self._writer = None
        self._count = 0
        if self._path.suffix == "":
            self._path.mkdir(parents=True, exist_ok=True)

    @property
    def frames_written(self) -> int:
        return self._count

    def write(self, image_bgr: np.ndarray) -> None:
        import cv2

        if self._path.suffix == "":
            cv2.imwrite(str(self._path / f"frame-{self._count:06d}.jpg"), image_bgr)
        else:
            if self._writer is None:
                h, w = image_bgr.shape[:2]
                fourcc = cv2.VideoWriter.fourcc(*"MJPG")
                self._writer = cv2.VideoWriter(str(self._path), fourcc, self._fps, (w, h))
                if not self._writer.isOpened():
                    raise OSError(f"{self._path}: cannot write a video here")
            self._writer.write(image_bgr)
        self._count += 1

    def close(self) -> None:
        if self._writer is not None:
            self._writer.release()
            self._writer = None


class MjpegServer:
    """Serves the newest overlaid frame as an MJPEG stream at http://host:port/ (host 127.0.0.1 unless
    the field laptop must reach it). Slow clients get the newest frame, never a backlog."""

    def __init__(self, *, host: str = "127.0.0.1", port: int = 0, max_fps: float = 10.0) -> None:
        self._cond = threading.Condition()
        self._jpeg: bytes | None = None
        self._seq = 0
        self._closed = False
        period = 1.0 / max_fps
        owner = self

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self) -> None:  # noqa: N802 - the http.server API
                self.send_response(200)
                self.send_header("Content-Type", "multipart/x-mixed-replace; boundary=" + BOUNDARY.decode())
                self.send_header("Cache-Control", "no-store")
                self.end_headers()
                seen = -1
                while True:
                    jpeg, seen = owner._next(seen, period * 5)
                    if owner._closed:
                        return
                    if jpeg is None:
                        continue
                    head = b"--%s\r\nContent-Type: image/jpeg\r\nContent-Length: %d\r\n\r\n" % (
                        BOUNDARY,
                        len(jpeg),
                    )
                    try:
                        self.wfile.write(head + jpeg + b"\r\n")
                    except OSError:
                        return

            def log_message(self, format: str, *args: object) -> None:  # noqa: A002 - http.server's name
                return None

        self._server = ThreadingHTTPServer((host, port), Handler)
        self._server.daemon_threads = True
        self._thread = threading.Thread(target=self._server.serve_forever, name="mjpeg", daemon=True)
        self._thread.start()

    def _next(self, seen: int, timeout_s: float) -> tuple[bytes | None, int]:
        """The newest JPEG once it is newer than seen (or after timeout_s), with its number."""
        with self._cond:
            self._cond.wait_for(lambda: self._seq != seen or self._closed, timeout=timeout_s)
            return self._jpeg, self._seq

    @property
    def port(self) -> int:
        return int(self._server.server_address[1])

    def publish(self, image_bgr: np.ndarray, *, quality: int = 80) -> None:
        import cv2

        ok, buf = cv2.imencode(".jpg", image_bgr, [cv2.IMWRITE_JPEG_QUALITY, quality])
        if ok:
            with self._cond:
                self._jpeg = buf.tobytes()
                self._seq += 1
                self._cond.notify_all()

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._server.shutdown()
        self._server.server_close()
