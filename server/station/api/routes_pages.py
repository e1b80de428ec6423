"""The pages: the landing page at / (the operator's 3-D page embedded full size, same origin), the sign-in
page, and /docs (Swagger UI from the installed wheel: the field laptop may have no internet). Scripts and
styles are files under /static (the pages carry no inline script, so their CSP allows none)."""

from __future__ import annotations

import html
from pathlib import Path

from fastapi import APIRouter, Request
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import HTMLResponse, RedirectResponse, Response

from server.station.api.deps import caller, gate_of
from server.station.api.display import display_query, sign_in_redirect_target

STATIC_DIR = Path(__file__).resolve().parent / "static"
router = APIRouter(include_in_schema=False)


def landing_page(*, operator_url: str, who: str, sign_out: bool) -> str:
    """The page at /: the operator's 3-D view embedded full size, with links to it, the API and the docs."""
    url = html.escape(operator_url, quote=True)
    out = '<button id="sign-out" type="button">sign out</button>' if sign_out else ""
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>skyring ground station</title>
<link rel="icon" href="data:,"><link rel="stylesheet" href="/static/skyring/site.css">
</head>
<body>
<header><b>skyring ground station</b>
<a id="operator-link" href="{url}" target="_blank">operator view (full window)</a>
<a href="/docs">API docs</a><a href="/api/state">state (JSON)</a>
<span id="who">{html.escape(who)}{out}</span></header>
<iframe id="operator-view" src="{url}" title="operator 3-D view"></iframe>
<script src="/static/skyring/landing.js"></script>
</body></html>"""


LOGIN_PAGE = """<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>skyring: sign in</title>
<link rel="icon" href="data:,"><link rel="stylesheet" href="/static/skyring/site.css"></head>
<body><header><b>skyring ground station</b></header>
<main class="login"><h1>Sign in</h1>
<form id="login">
<label for="name">Name</label><input id="name" name="name" autocomplete="username" required autofocus>
<label for="secret">Secret</label>
<input id="secret" name="secret" type="password" autocomplete="current-password" required>
<button id="sign-in" type="submit">Sign in</button>
<div id="error" role="alert"></div>
</form></main>
<script src="/static/skyring/login.js"></script>
</body></html>"""


@router.get("/", response_class=HTMLResponse)
def index(request: Request) -> Response:
    principal = caller(request)
    gate = gate_of(request)
    if principal.role is None:
        return RedirectResponse(sign_in_redirect_target("/", request), status_code=303)
    who = (
        "local operator (no sign-in on loopback)"
        if gate.open
        else f"{principal.name} ({principal.role.value})"
    )
    return HTMLResponse(
        landing_page(operator_url="/operator/" + display_query(request), who=who, sign_out=not gate.open)
    )


@router.get("/login", response_class=HTMLResponse)
def login_page() -> HTMLResponse:
    return HTMLResponse(LOGIN_PAGE)


@router.get("/docs", response_class=HTMLResponse)
def docs(request: Request) -> HTMLResponse:
    return get_swagger_ui_html(
        openapi_url=request.app.openapi_url,
        title="skyring API",
        swagger_js_url="/static/swagger/swagger-ui-bundle.js",
        swagger_css_url="/static/swagger/swagger-ui.css",
        swagger_favicon_url="/static/swagger/favicon-32x32.png",
    )
