"""The live plots: per-vehicle altitude and speed, the fused covariance trace and the tracking error, over
mission seconds.

`PlotHistory` (pure) keeps a sample every `sample_period_s` of mission time over the last `window_s`; a value
that is missing at an instant (no estimate yet, a vehicle without telemetry) is NaN there. `LivePlots` sends
the history to viser's uPlot charts with every NaN as null: uPlot draws null as a gap, whereas a NaN in the
data makes it compute a NaN axis range and draw nothing at all (which left the plots empty until the NaN
samples had scrolled out of the window). viser's `data` setter casts every series to a float64 array, so the
lists with nulls go out through the handle's own update message instead (`_queue_update`, the call the setter
itself ends in); the charts' x axis is plain seconds (uPlot's default is a date axis).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import viser
import viser.uplot

from webui.view import SceneView

WINDOW_S = 120.0  # mission seconds the plots show
SAMPLE_PERIOD_S = 0.25  # mission seconds between two plotted samples


@dataclass(frozen=True)
class PlotSample:
    """One instant: time_s; altitude_m / speed_mps per vehicle, in `PlotHistory.vehicle_ids` order (NaN when
    unknown); trace_m2: fused position-covariance trace; error_m: tracking error (NaN when unknown)."""

    time_s: float
    altitude_m: tuple[float, ...]
    speed_mps: tuple[float, ...]
    trace_m2: float
    error_m: float


class PlotHistory:
    """The last window_s of mission time, one sample every sample_period_s."""

    def __init__(
        self,
        vehicle_ids: Sequence[int],
        *,
        window_s: float = WINDOW_S,
        sample_period_s: float = SAMPLE_PERIOD_S,
    ) -> None:
        self.vehicle_ids = tuple(vehicle_ids)
        self._window_s = window_s
        self._period_s = sample_period_s
        self._samples: deque[PlotSample] = deque()

    def record(self, view: SceneView) -> bool:
        """Add a sample of `view` if sample_period_s has passed since the last one; True if it was added."""
        if self._samples and view.time_s < self._samples[-1].time_s + self._period_s - 1e-9:
            return False
        by_id = {v.vehicle_id: v for v in view.vehicles}
        altitude, speed = [], []
        for vid in self.vehicle_ids:
            v = by_id.get(vid)
            fresh = v is not None and not v.link_stale
            altitude.append(v.altitude_m if fresh and v is not None else math.nan)
            speed.append(v.speed_mps if fresh and v is not None else math.nan)
        estimate = view.person_estimate
        self._samples.append(
            PlotSample(
                time_s=view.time_s,
                altitude_m=tuple(altitude),
                speed_mps=tuple(speed),
                trace_m2=estimate.position_cov_trace_m2 if estimate is not None else math.nan,
                error_m=view.tracking_error_m if view.tracking_error_m is not None else math.nan,
            )
        )
        while self._samples and self._samples[0].time_s < view.time_s - self._window_s:
            self._samples.popleft()
        return True

    def __len__(self) -> int:
        return len(self._samples)

    def times(self) -> np.ndarray:
        """(n,) mission seconds of the samples."""
        return np.array([s.time_s for s in self._samples])

    def altitudes(self) -> np.ndarray:
        """(n, K) altitude of each vehicle (NaN where unknown)."""
        return np.array([s.altitude_m for s in self._samples]).reshape(len(self._samples), -1)

    def speeds(self) -> np.ndarray:
        """(n, K) speed of each vehicle (NaN where unknown)."""
        return np.array([s.speed_mps for s in self._samples]).reshape(len(self._samples), -1)

    def traces(self) -> np.ndarray:
        return np.array([s.trace_m2 for s in self._samples])

    def errors(self) -> np.ndarray:
        return np.array([s.error_m for s in self._samples])


def with_gaps(values: np.ndarray, digits: int = 3) -> list[float | None]:
    """A series as uPlot wants it: numbers rounded to `digits` decimals, None (a gap) for NaN/inf."""
    return [round(float(v), digits) if math.isfinite(v) else None for v in np.asarray(values, dtype=float)]


def _rgb(color: tuple[int, int, int]) -> str:
    return "rgb({},{},{})".format(*color)


def _chart(
    gui: viser.GuiApi, title: str, labels: Sequence[tuple[str, tuple[int, int, int]]], unit: str
) -> viser.GuiUplotHandle:
    empty = tuple(np.zeros(0) for _ in range(len(labels) + 1))
    series = (viser.uplot.Series(label="t (s)"),) + tuple(
        viser.uplot.Series(label=label, stroke=_rgb(color), width=2, spanGaps=False)
        for label, color in labels
    )
    axes: tuple[Any, ...] = (
        viser.uplot.Axis(label="mission time (s)"),
        viser.uplot.Axis(label=unit, size=46),
    )
    return gui.add_uplot(
        empty,
        series,
        title=title,
        # range (None, None): the x axis spans the data, recomputed on every update (viser's default instead
        # keeps the previous zoom relative to the data, which breaks when the data arrive in a hidden tab)
        scales={"x": viser.uplot.Scale(time=False, range=(None, None))},  # type: ignore[typeddict-item]
        axes=axes,
        aspect=1.8,
    )


class LivePlots:
    """Four uPlot charts in the current GUI container, fed from a `PlotHistory`."""

    def __init__(
        self, gui: viser.GuiApi, vehicle_ids: Sequence[int], colors: dict[int, tuple[int, int, int]]
    ) -> None:
        per_vehicle = [(f"MAV {vid}", colors[vid]) for vid in vehicle_ids]
        self.altitude = _chart(gui, "Altitude per MAV", per_vehicle, "m")
        self.speed = _chart(gui, "Speed per MAV", per_vehicle, "m/s")
        self.trace = _chart(gui, "Fused position covariance trace", [("trace (m^2)", (200, 140, 0))], "m^2")
        self.error = _chart(gui, "Tracking error (simulation)", [("error (m)", (200, 40, 40))], "m")
        self.sent: dict[str, tuple[list[float | None], ...]] = {}  # what each chart was last sent

    def push(self, history: PlotHistory) -> None:
        """Send the whole history to every chart (gaps as nulls)."""
        t = with_gaps(history.times())
        alt, speed = history.altitudes(), history.speeds()
        self._send("altitude", self.altitude, (t, *(with_gaps(alt[:, k]) for k in range(alt.shape[1]))))
        self._send("speed", self.speed, (t, *(with_gaps(speed[:, k]) for k in range(speed.shape[1]))))
        self._send("trace", self.trace, (t, with_gaps(history.traces(), 4)))
        self._send("error", self.error, (t, with_gaps(history.errors())))

    def _send(self, name: str, handle: viser.GuiUplotHandle, data: tuple[list[float | None], ...]) -> None:
        self.sent[name] = data
        handle._queue_update("data", data)  # noqa: SLF001 - see the module docstring: nulls for gaps
