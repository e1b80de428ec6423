// The landing page's sign-out button, and the embedded operator page focused once loaded: keys go to it (its
// Shift+L opens LAND ALL) unless the operator clicks elsewhere.
"use strict";
const view = document.getElementById("operator-view");
if (view) {
  // At once (the frame keeps the focus while its page loads) and again once loaded, in case the operator
  // clicked the header meanwhile.
  view.focus();
  view.addEventListener("load", () => view.focus());
}
const out = document.getElementById("sign-out");
if (out) {
  out.addEventListener("click", async () => {
    await fetch("/auth/logout", { method: "POST", credentials: "same-origin" });
    window.location.assign("/login");
  });
}
