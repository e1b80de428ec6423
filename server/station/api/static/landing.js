// The landing page's sign-out button.
"use strict";
const out = document.getElementById("sign-out");
if (out) {
  out.addEventListener("click", async () => {
    await fetch("/auth/logout", { method: "POST", credentials: "same-origin" });
    window.location.assign("/login");
  });
}
