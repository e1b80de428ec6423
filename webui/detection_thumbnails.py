"""Each MAV's latest detection thumbnail in the operator page, about once a second, with its camera's state.

A separate, small piece of the page: a "Cameras" folder (made when the first report arrives) with one entry
per MAV (in vehicle order, next to the vehicle cards), fed by whoever receives the `skyring detect` reports
(the ground station). The JPEG that `skyring detect` made (overlay drawn, 320 px wide) is shown as it is, in
an <img> with a data URI: no decoding here, no request back to the MAV. Updates faster than `min_period_s`
per MAV are dropped, so a flood of reports cannot load the page. `mark_stale` (called about once a second)
flags a MAV whose reports stopped (its detector process died, or its link did) with the picture's age.
"""

from __future__ import annotations

import base64
import html
import math
import threading
import time
from collections.abc import Callable

import viser

IMG_STYLE = "width:100%;display:block"


def thumbnail_html(vehicle_id: int, jpeg: bytes | None, caption: str) -> str:
    """The HTML of one MAV's entry: the picture (or a placeholder) and a one-line caption."""
    if jpeg:
        src = "data:image/jpeg;base64," + base64.b64encode(jpeg).decode()
        img = f'<img class="skyring-thumb" data-vehicle="{vehicle_id}" src="{src}" style="{IMG_STYLE}">'
    else:
        img = f'<div class="skyring-thumb-empty" data-vehicle="{vehicle_id}">no picture yet</div>'
    return (
        f'<div style="margin:2px 0 6px 0"><div style="font-size:0.8em"><b>MAV {vehicle_id}</b> '
        f"{html.escape(caption)}</div>{img}</div>"
    )


class DetectionThumbnails:
    """The Cameras folder of the operator page. `update` may be called from any thread."""

    def __init__(
        self,
        server: viser.ViserServer,
        *,
        min_period_s: float = 1.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._server = server
        self._min_period_s = float(min_period_s)
        self._clock = clock
        self._lock = threading.Lock()
        self._folder: viser.GuiFolderHandle | None = None  # made with the first picture: no empty folder
        self._entries: dict[int, viser.GuiHtmlHandle] = {}
        self._shown_at: dict[int, float] = {}
        self._shown: dict[int, tuple[bytes | None, str]] = {}
        self._stale: set[int] = set()
        self.closed = threading.Event()
        self.dropped = 0

    def update(self, vehicle_id: int, jpeg: bytes | None, caption: str) -> bool:
        """Show vehicle_id's latest picture and caption; False when dropped (too soon after the last)."""
        now = self._clock()
        if self.closed.is_set():
            return False
        with self._lock:
            last = self._shown_at.get(vehicle_id, -math.inf)
            if now - last < self._min_period_s:
                self.dropped += 1
                return False
            self._shown_at[vehicle_id] = now
            self._shown[vehicle_id] = (jpeg, caption)
            self._stale.discard(vehicle_id)
            content = thumbnail_html(vehicle_id, jpeg, caption)
            handle = self._entries.get(vehicle_id)
            if self._folder is None:
                self._folder = self._server.gui.add_folder("Cameras", expand_by_default=True)
            if handle is None:
                with self._folder:
                    self._entries[vehicle_id] = self._server.gui.add_html(content, order=float(vehicle_id))
            else:
                handle.content = content
        return True

    def mark_stale(self, *, max_age_s: float = 3.0) -> list[int]:
        """Flag every MAV whose last picture is older than max_age_s ("NO REPORT for N s"); returns them."""
        now = self._clock()
        flagged: list[int] = []
        if self.closed.is_set():
            return flagged
        with self._lock:
            for vid, shown_at in self._shown_at.items():
                age = now - shown_at
                handle = self._entries.get(vid)
                if age <= max_age_s or handle is None:
                    continue
                jpeg, caption = self._shown[vid]
                handle.content = thumbnail_html(vid, jpeg, f"NO REPORT for {age:.0f} s (last: {caption})")
                self._stale.add(vid)
                flagged.append(vid)
        return flagged

    def close(self) -> None:
        """Stop touching the page (before its server stops)."""
        self.closed.set()

    def remove(self, vehicle_id: int) -> None:
        with self._lock:
            handle = self._entries.pop(vehicle_id, None)
            self._shown_at.pop(vehicle_id, None)
            self._shown.pop(vehicle_id, None)
        if handle is not None:
            handle.remove()
