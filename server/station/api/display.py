"""The operator page's display setting that the station's own pages carry along: viser's `fixedDpr`, the 3-D
view's pixel ratio. A laptop that renders WebGL in software (no GPU driver) opens `/?fixedDpr=0.5` and keeps
the controls responsive; the landing page hands the setting to the embedded view, and the sign-in redirects
bring the operator back to the page as asked for. Anything else in the query is not passed on."""

from __future__ import annotations

import math
from urllib.parse import quote

from fastapi import Request

FIXED_DPR_RANGE = (0.1, 4.0)
"""The pixel ratios passed on (device pixels per CSS pixel); a value outside is dropped, not clamped."""


def display_query(request: Request) -> str:
    """`?fixedDpr=X` when the request asks for a valid pixel ratio, else the empty string."""
    raw = request.query_params.get("fixedDpr")
    if raw is None:
        return ""
    try:
        dpr = float(raw)
    except ValueError:
        return ""
    low, high = FIXED_DPR_RANGE
    if not (math.isfinite(dpr) and low <= dpr <= high):
        return ""
    return f"?fixedDpr={dpr:g}"


def sign_in_redirect_target(path: str, request: Request) -> str:
    """The sign-in page's address that comes back to `path` (a path on this station), with the display
    setting of `request`."""
    return "/login?next=" + quote(path + display_query(request), safe="/")
