// The sign-in form: POST /auth/login as JSON (the session cookie comes back HttpOnly), then go on.
"use strict";
document.getElementById("login").addEventListener("submit", async (event) => {
  event.preventDefault();
  const error = document.getElementById("error");
  error.textContent = "";
  const body = JSON.stringify({
    name: document.getElementById("name").value,
    secret: document.getElementById("secret").value,
  });
  const reply = await fetch("/auth/login", {
    method: "POST",
    headers: { "content-type": "application/json" },
    body,
    credentials: "same-origin",
  });
  if (reply.ok) {
    const next = new URLSearchParams(window.location.search).get("next") || "/";
    window.location.assign(next.startsWith("/") && !next.startsWith("//") ? next : "/");
  } else {
    const problem = await reply.json().catch(() => ({ detail: reply.statusText }));
    error.textContent = problem.detail || "sign-in failed";
  }
});
